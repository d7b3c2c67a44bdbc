"""Current waypoint from the closest plan *segment*, with the plan time breaking ties."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import FRAME, T0, plan_from_local

from gcs_utm.core.tracking import PlanTable, current_waypoint
from gcs_utm.model import FlightPlan


def _plan(op_id: str, points: list[tuple[float, float, float, float]]) -> FlightPlan:
    """Plan with times relative to T0."""
    return plan_from_local(op_id, [(e, n, a, T0 + t) for e, n, a, t in points])


def _wp(plan: FlightPlan, e: float, n: float, t: float, ambiguity_m: float = 5.0) -> int:
    return current_waypoint(
        plan, FRAME, east_m=e, north_m=n, alt_amsl_m=100.0, t_s=T0 + t, ambiguity_m=ambiguity_m
    )


# Lawn-mower: lanes 200 m long, 20 m apart, flown at 10 m/s.
#  wp0 (0,0) -> wp1 (200,0) -> wp2 (200,20) -> wp3 (0,20) -> wp4 (0,40) -> wp5 (200,40)
LAWN = _plan(
    "lawn",
    [
        (0, 0, 100, 0),
        (200, 0, 100, 20),
        (200, 20, 100, 22),
        (0, 20, 100, 42),
        (0, 40, 100, 44),
        (200, 40, 100, 64),
    ],
)


def test_lawn_mower_uses_the_segment_not_the_closest_vertex() -> None:
    # On lane 2 (flying west) near its east end: the closest *vertex* is wp1/wp2 (behind),
    # the closest segment is lane 2, so the UAS is flying to wp3.
    assert _wp(LAWN, 190, 21, 23) == 3
    # Near the west end of lane 1 (flying east), the closest vertex is wp0, but the UAS flies
    # to wp1; wp3 (0, 20) is as close as wp0 is to a point at (10, 10).
    assert _wp(LAWN, 10, 9, 1) == 1
    # In the middle of lane 3 (flying east) it flies to wp5.
    assert _wp(LAWN, 100, 41, 54) == 5
    # On the connector between lanes.
    assert _wp(LAWN, 200, 10, 21) == 2


def test_reaching_a_waypoint_hands_over_to_the_next() -> None:
    assert _wp(LAWN, 200, 0, 20) == 2
    assert _wp(LAWN, 205, -3, 20) == 2


# A square loop flown twice: the same place is on two segments, 40 s apart in the plan.
LOOP = _plan(
    "loop",
    [
        (0, 0, 100, 0),
        (100, 0, 100, 10),
        (100, 100, 100, 20),
        (0, 100, 100, 30),
        (0, 0, 100, 40),
        (100, 0, 100, 50),
        (100, 100, 100, 60),
        (0, 100, 100, 70),
        (0, 0, 100, 80),
    ],
)


def test_loop_plan_uses_the_plan_time_to_choose_the_lap() -> None:
    assert _wp(LOOP, 50, 1, 5) == 1
    assert _wp(LOOP, 50, 1, 45) == 5
    # A UAS 8 s late on lap two is still on lap two.
    assert _wp(LOOP, 50, 1, 53) == 5
    assert _wp(LOOP, 100, 60, 16) == 2
    assert _wp(LOOP, 100, 60, 57) == 6


def test_geometry_beats_time_beyond_the_ambiguity() -> None:
    # Far ahead of schedule on lane 3 of the lawn-mower, time says lane 1 but the geometry
    # (20 m away, ambiguity 5 m) rules lane 1 out.
    assert _wp(LAWN, 100, 40, 5) == 5


def test_single_waypoint_plan() -> None:
    plan = _plan("hover", [(0, 0, 100, 0)])
    assert _wp(plan, 30, 30, 0) == 0


@settings(max_examples=40, deadline=None)
@given(
    n_wp=st.integers(1, 8),
    seed=st.integers(0, 2**32 - 1),
    first_ahead_s=st.floats(-30.0, 100.0),
    step_s=st.sampled_from([0.25, 1.0, 3.0]),
)
def test_follow_matches_linear_interpolation_of_the_plan(
    n_wp: int, seed: int, first_ahead_s: float, step_s: float
) -> None:
    rng = np.random.default_rng(seed)
    plans = []
    for j in range(3):  # several plans in one table: rows must not leak into each other
        # Durations include zeros (two waypoints at the same time).
        dts = rng.choice([0.0, 2.0, 5.0, 7.5], size=n_wp)
        dts[0] = 0.0
        t = T0 + 10.0 * j + np.cumsum(dts)
        pts = rng.uniform(-500, 500, size=(n_wp, 3)) + np.array([0.0, 0.0, 600.0])
        plans.append(_plan(f"p{j}", [(*p, tt - T0) for p, tt in zip(pts, t, strict=True)]))
    table = PlanTable(plans, FRAME)
    rows = np.array([2, 0, 1, 2], dtype=np.intp)
    tau0 = np.array([T0 + 3.0, T0 - 5.0, T0 + 40.0, T0 + 25.0])
    k = 25
    east, north, alt = table.follow(rows, tau0, np.full(4, first_ahead_s), step_s, k)
    for i, j in enumerate(rows):
        o, m = int(table.wp_offset[j]), int(table.n_waypoints[j])
        wt = table.wp_t[o : o + m]
        wp = table.wp_pos[o : o + m]
        raw = tau0[i] + first_ahead_s + np.arange(k) * step_s
        tau = np.clip(raw, wt[0], wt[-1])
        for axis, got in enumerate((east, north, alt)):
            # At a repeated time the plan has moved on to the later point (as np.interp);
            # before the plan starts the UAS waits at the first waypoint.
            want = np.interp(tau, wt, wp[:, axis]) if m > 1 else np.full(k, wp[0, axis])
            want = np.where(raw < wt[0], wp[0, axis], want)
            # A repeated time is a jump in the plan: within rounding of that instant either
            # side of the jump is right, so those samples are not compared.
            jumps = wt[1:][np.diff(wt) == 0.0]
            keep = np.ones(k, dtype=bool)
            for tj in jumps:
                keep &= np.abs(raw - tj) > 1e-6
            # POSIX times carry ~2e-7 s of rounding; at <= 100 m/s that is < 1e-4 m.
            np.testing.assert_allclose(got[i][keep], want[keep], atol=1e-4)
