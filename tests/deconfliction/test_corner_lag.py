"""A multirotor loses time at each corner of its plan and never makes it up: TD verifies a new
plan also as flown late by its corners (issue 30, a loss created by an accepted plan:
enc_2_0009, three corners of a lateral deformation, 48.8 m flown where the plan kept
60.8 m against minima of 50 m plus the tolerances)."""

from __future__ import annotations

import math

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction.corner_lag import corner_losses_s, lagged
from gcs_utm.core.deconfliction.geometry import LocalPlan, plan_to_local

ALT_M = 100.0
SIDE_M = 200.0 * math.sin(math.radians(60.0))  # the north offset of the last leg


def test_each_corner_costs_half_the_velocity_change_over_the_acceleration() -> None:
    # east at 10 m/s, a 60 degree turn, a 60 degree turn back, then east: dv = 10 m/s twice
    lp = LocalPlan(
        np.array([0.0, 300.0, 400.0, 700.0]),
        np.array([0.0, 0.0, SIDE_M, SIDE_M]),
        np.full(4, ALT_M),
        np.array([0.0, 30.0, 50.0, 80.0]),
    )
    assert np.allclose(corner_losses_s(lp, 2.5), [0.0, 2.0, 2.0, 0.0])
    late = lagged(lp, 2.5)
    assert late is not None and np.allclose(late.t, [0.0, 32.0, 54.0, 84.0])
    straight = LocalPlan(
        np.array([0.0, 300.0, 600.0]), np.zeros(3), np.full(3, ALT_M), np.array([0, 30.0, 60.0])
    )
    assert lagged(straight, 2.5) is None


def test_a_plan_whose_corners_bring_it_late_onto_a_trailing_uas_is_refused() -> None:
    """M turns twice (4 s lost at 2.5 m/s^2) onto the line O flies behind it at the same
    speed: the plan keeps the buffered minima from O, M flown late does not."""
    td = sc.build_manager().td
    t0 = sc.T0_S
    m = sc.make_operation(
        "M",
        [(0.0, 0.0, ALT_M), (300.0, 0.0, ALT_M), (400.0, SIDE_M, ALT_M), (900.0, SIDE_M, ALT_M)],
        t0_s=t0,
    )
    h_min, _ = td.monitoring.effective_minima(10.0, 10.0)
    behind_m = h_min + 15.0  # more than the minima plus both tracking tolerances (5 m each)
    # O reaches M's second corner behind_m after M does (at t0 + 50 s), same line, same speed
    start_e = 400.0 - behind_m - 10.0 * 50.0
    o = sc.make_operation("O", [(start_e, SIDE_M, ALT_M), (1200.0, SIDE_M, ALT_M)], t0_s=t0)
    lm, lo = plan_to_local(m.plan, sc.FRAME), plan_to_local(o.plan, sc.FRAME)
    t = np.arange(t0, t0 + 90.0, 0.5)
    me, mn, _ = lm.coords(t)
    oe, on, _ = lo.coords(t)
    assert np.hypot(me - oe, mn - on).min() >= behind_m - 0.5  # the plans keep it
    flags = td.verify(m.plan, m, [o], ())
    assert any("as flown late at its corners: separation with O" in f for f in flags), flags
    # O further behind than the 4 s M loses: clear as flown too
    far = sc.make_operation(
        "O", [(start_e - 45.0, SIDE_M, ALT_M), (1200.0, SIDE_M, ALT_M)], t0_s=t0
    )
    assert td.verify(m.plan, m, [far], ()) == []
