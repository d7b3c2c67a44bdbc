"""A UAS holding where its plan holds (two waypoints at one place, EM's "delay") is on
schedule: its plan time is its own time while the hold lasts, not the hold's start or end,
whichever is nearer (a UAS 12 s into a 25 s hold was taken as 12 s early, and Monitoring
predicted it leaving then)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import FRAME, T0, plan_from_local

from gcs_utm.core.tracking import PlanTable

# To (100, 0) in 10 s, hold there until 35 s, then on to (300, 0) by 55 s.
HOLD = plan_from_local(
    "hold",
    [(0, 0, 100, T0), (100, 0, 100, T0 + 10), (100, 0, 100, T0 + 35), (300, 0, 100, T0 + 55)],
)


def _tau(e: float, t: float, hint: int | None = None) -> tuple[float, int]:
    table = PlanTable([HOLD], FRAME)
    wp, _, tau, _ = table.locate(
        np.zeros(1, dtype=np.intp),
        np.array([[e, 0.0, 100.0]]),
        np.array([T0 + t]),
        np.array([5.0]),
        hint=None if hint is None else np.array([hint], dtype=np.intp),
    )
    return float(tau[0]) - T0, int(wp[0])


def test_a_uas_on_its_hold_is_on_schedule() -> None:
    for t in (11.0, 15.0, 22.0, 23.0, 30.0, 34.0):
        tau, wp = _tau(100.0, t)
        assert abs(tau - t) < 1e-6, (t, tau)
        assert wp == 2  # it waits for the hold's end before flying to waypoint 3
        assert abs(_tau(100.0, t, hint=1)[0] - t) < 1e-6


def test_before_and_after_its_hold_it_is_late_or_early() -> None:
    # At the hold point before the hold begins: early by the difference; after it ends:
    # late by the difference (it has not left yet).
    assert abs(_tau(100.0, 8.0)[0] - 10.0) < 1e-6
    assert abs(_tau(100.0, 40.0)[0] - 35.0) < 1e-6
    # On the legs around it nothing changes.
    assert abs(_tau(50.0, 5.0)[0] - 5.0) < 1e-6
    assert abs(_tau(200.0, 45.0)[0] - 45.0) < 1e-6
