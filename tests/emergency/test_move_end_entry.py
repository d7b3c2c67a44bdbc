"""A fixed wing's moved end point is cleared with the loop it flies entering its circle
(issue 30, a loss created by an accepted plan: enc_5_0320_crossing, UAS3's end moved 80 m,
231 m from UAS4's circling end; entering its circle from the end point it looped out 119 m
towards UAS4, 39.4 m / 14.1 m against 50 / 50 m)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from gcs_utm.core.emergency.circle_entry import entry_loop, entry_reach_m

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_move_end import F1, F2, _scene, loiter, plan_to_local, sc

from gcs_utm.model import ThreatKind


def test_the_entry_loop_swings_out_to_the_right_within_its_reach() -> None:
    """The loop EM verifies is the tracker's capture: out past the circle on the right of an
    eastbound arrival (the wider the faster), never beyond :func:`entry_reach_m`, settling
    near the circle."""
    end = np.array([0.0, 0.0, 100.0])
    farthest = []
    for speed in (20.0, 22.7, 25.0):
        e, n, t = entry_loop(end, 0.0, 80.0, speed, 1.0)  # arriving heading east
        d = np.hypot(e, n)
        far = int(np.argmax(d))
        farthest.append(float(d[far]))
        assert 80.0 * 1.4 < d[far] <= entry_reach_m(80.0, speed)
        assert n[far] < -100.0  # to the right of an eastbound arrival
        assert abs(float(d[-1]) - 80.0) < 0.2 * 80.0  # settling onto the circle
        assert np.all(np.diff(t) > 0.0)
        steps = np.hypot(np.diff(e), np.diff(n))
        assert float(steps.max()) < 2.0 * speed * 1.0  # no jump: a flyable path, sampled
    assert farthest == sorted(farthest)


def test_a_moved_end_point_keeps_the_entry_loop_clear_of_the_other_circle() -> None:
    snap = _scene()  # F1 and F2 circling 150 m apart; F1 (the lower priority) moves
    em = sc.build_manager()
    los = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["F1", "F2"], event_in_s=40.0)
    (rec,) = em.on_threat(los, snap).recommendations
    assert rec.operation_id == F1 and rec.selected is not None and rec.selected.plan is not None
    new_end = plan_to_local(rec.selected.plan, sc.FRAME).xyz()[-1]
    f1, f2 = snap.operations[F1], snap.operations[F2]
    r1, r2 = loiter.loiter_radius_m(f1), loiter.loiter_radius_m(f2)
    h_m, v_m = em.td.pair_minima(f1, f2)
    apart = math.hypot(float(new_end[0]) - 150.0, float(new_end[1]))
    # F1's loop reaches entry_reach_m from its new end, F2 circles one of its own radii
    reach_m = entry_reach_m(r1, f1.cruise_speed_mps)
    assert apart >= h_m + reach_m + r2 - 1e-6 or abs(new_end[2] - 100.0) >= v_m
