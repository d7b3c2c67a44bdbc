"""An altitude offset from the plan that persists is kept in the prediction; a single noisy
sample or an offset that changes side is not (see gcs_utm/core/tracking/offsets.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import T0, meas, new_tracker, operation, plan_from_local

from gcs_utm.core.tracking import Tracker
from gcs_utm.core.tracking.offsets import AltitudeOffsets

PLAN_ALT_M = 100.0


def _flown(alt_of_k: list[float]) -> tuple[Tracker, float]:
    """A track flying its plan (east at 10 m/s, 100 m AMSL) at the altitudes given, one
    measurement and one prediction a second (Monitoring's cycle); returns the tracker and
    the last time."""
    plan = plan_from_local("op1", [(0, 0, PLAN_ALT_M, T0), (3000, 0, PLAN_ALT_M, T0 + 300)])
    tr = new_tracker()
    tr.set_operations([operation("op1", plan, sys_id=1, flight_geometry_m=10.0)])
    for k, alt in enumerate(alt_of_k):
        tr.ingest([meas(10.0 * k, 0.0, alt, T0 + k, eph_m=0.5, epv_m=0.3)])
        tr.predict(T0 + k)
    return tr, T0 + len(alt_of_k) - 1


def test_a_persistent_altitude_offset_is_kept_over_the_horizon() -> None:
    # 1.5 m above the plan (with +-0.2 m of noise) for 25 s. Before, the prediction decayed
    # the offset with plan_offset_decay_s (10 s): 60 s ahead it was gone (1.5 e^-6 = 4 mm),
    # and a pass that close to the vertical minimum was predicted seconds before it.
    noise = [0.2, -0.2, 0.1, -0.1, 0.0]
    tr, t = _flown([PLAN_ALT_M + 1.5 + noise[k % 5] for k in range(25)])
    pred = tr.predict(t)
    far = pred.points[0, -1, 2] - PLAN_ALT_M
    assert 1.0 < far <= 1.7
    # A second prediction at the same time (no new measurement) gives the same answer.
    assert tr.predict(t).points[0, -1, 2] == pred.points[0, -1, 2]


def test_a_single_noisy_sample_is_not_a_persistent_offset() -> None:
    alts = [PLAN_ALT_M] * 25
    alts[20] = PLAN_ALT_M + 3.0  # one bad altitude
    tr, t = _flown(alts)
    assert abs(tr.predict(t).points[0, -1, 2] - PLAN_ALT_M) < 0.05


def test_an_offset_that_changes_side_does_not_persist() -> None:
    # Altitude oscillating 1.5 m either side of the plan every 4 s: no side persists.
    tr, t = _flown([PLAN_ALT_M + (1.5 if (k // 4) % 2 else -1.5) for k in range(30)])
    assert abs(tr.predict(t).points[0, -1, 2] - PLAN_ALT_M) < 0.05


def test_the_persistent_size_is_the_smallest_over_the_last_windows() -> None:
    off = AltitudeOffsets(window_s=10.0)
    off.grow(4, 0)
    rows = np.array([0], dtype=np.intp)
    for k in range(10):
        off.observe(rows, np.array([float(k)]), np.array([-2.0 - 0.1 * k]))
    assert off.persistent(rows)[0] == 0.0  # 9 s: not yet a window
    off.observe(rows, np.array([10.0]), np.array([-3.0]))
    assert off.persistent(rows)[0] == -2.0  # the smallest size since the run began
    for k in range(11, 31):
        off.observe(rows, np.array([float(k)]), np.array([-3.0]))
    assert off.persistent(rows)[0] == -3.0  # the -2 m samples are two windows old
    off.observe(rows, np.array([31.0]), np.array([-0.5]))
    assert off.persistent(rows)[0] == -0.5  # a shrinking offset is followed at once
    off.observe(rows, np.array([32.0]), np.array([0.5]))
    assert off.persistent(rows)[0] == 0.0  # other side: starts over
