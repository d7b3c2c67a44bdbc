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


# ---- windowed search from the previous segment ---------------------------------------------


def _locate(
    table: PlanTable, e: float, n: float, t: float, amb: float, hint: int | None
) -> tuple[int, float, float, int]:
    wp, dist, tau, seg = table.locate(
        np.zeros(1, dtype=np.intp),
        np.array([[e, n, 100.0]]),
        np.array([T0 + t]),
        np.array([amb]),
        hint=None if hint is None else np.array([hint], dtype=np.intp),
    )
    return int(wp[0]), float(dist[0]), float(tau[0]), int(seg[0])


def test_window_answers_from_the_previous_segment() -> None:
    table = PlanTable([LOOP], FRAME)
    # Lap two, hint on the segment it is flying: answered by the window, same as full.
    assert _locate(table, 50, 1, 45, 5.0, 4)[0] == 5
    assert table.searches == {"window": 1, "full": 0}
    assert _locate(table, 50, 1, 45, 5.0, None)[0] == 5
    assert table.searches == {"window": 1, "full": 1}


def test_stale_hint_on_a_revisited_place_falls_back_to_the_full_search() -> None:
    table = PlanTable([LOOP], FRAME)
    # The UAS is on lap two at the same place as lap one's first segment; a hint left on
    # lap one would find the right place at the wrong lap. Its plan time gives it away.
    assert _locate(table, 50, 1, 45, 5.0, 0)[0] == 5
    assert table.searches == {"window": 0, "full": 1}
    # The other way round: on lap one with a hint on lap two.
    assert _locate(table, 50, 1, 5, 5.0, 5)[0] == 1
    assert table.searches == {"window": 0, "full": 2}


def test_hint_far_from_the_track_falls_back() -> None:
    table = PlanTable([LAWN], FRAME)
    # On lane 3 (to wp5) with a hint on lane 1: the window's closest point is 20 m away.
    assert _locate(table, 100, 41, 54, 5.0, 0)[0] == 5
    assert table.searches["full"] == 1
    # Off the plan altogether: full search, as without a hint.
    got = _locate(table, 100, 300, 54, 5.0, 4)
    assert got == _locate(table, 100, 300, 54, 5.0, None)
    assert table.searches == {"window": 0, "full": 3}


def _revisiting_plan(rng: np.random.Generator, kind: int) -> FlightPlan:
    """Lawn-mower with lanes closer than the ambiguity, a loop flown three times, or a
    random walk with hovers (repeated points): all revisit places."""
    if kind == 0:
        pts: list[tuple[float, float]] = []
        for lane in range(8):
            xs = (0.0, 120.0) if lane % 2 == 0 else (120.0, 0.0)
            pts += [(xs[0], 4.0 * lane), (xs[1], 4.0 * lane)]
    elif kind == 1:
        square = [(0.0, 0.0), (80.0, 0.0), (80.0, 80.0), (0.0, 80.0)]
        pts = square * 3 + square[:1]
    else:
        steps = rng.normal(size=(25, 2)) * 40.0
        steps[rng.random(25) < 0.2] = 0.0
        walk = np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])
        pts = [(float(a), float(b)) for a, b in walk]
    t = 0.0
    out = []
    for i, (e, n) in enumerate(pts):
        if i:
            d = float(np.hypot(e - pts[i - 1][0], n - pts[i - 1][1]))
            t += d / 10.0 if d > 0 else 3.0
        out.append((e, n, 100.0, t))
    return _plan(f"r{kind}", out)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_windowed_search_equals_the_full_search(seed: int) -> None:
    """Whatever the hint (right, neighbouring, stale, another lap, none), the answer is
    the full search's: same segment, waypoint and plan time; the distance may be the
    window's only where that is within the ambiguity (it decides nothing then)."""
    rng = np.random.default_rng(seed)
    plans = [_revisiting_plan(rng, kind) for kind in range(3)]
    table = PlanTable(plans, FRAME)
    n = 400
    plan_idx = rng.integers(0, 3, size=n).astype(np.intp)
    # Positions near the plan at a plan time, flown early/late and off track by a bit.
    t_true = np.empty(n)
    pos = np.empty((n, 3))
    for i, j in enumerate(plan_idx):
        o, m = int(table.wp_offset[j]), int(table.n_waypoints[j])
        wt = table.wp_t[o : o + m]
        t_true[i] = rng.uniform(wt[0], wt[-1])
        for axis in range(3):
            pos[i, axis] = np.interp(t_true[i], wt, table.wp_pos[o : o + m, axis])
    pos += rng.normal(size=(n, 3)) * rng.choice([0.5, 3.0, 15.0], size=(n, 1))
    t_s = t_true + rng.choice([0.0, 0.0, 4.0, -4.0, 30.0], size=n)
    amb = rng.choice([0.0, 5.0, 10.0], size=n)
    _, _, _, right = table.locate(plan_idx, pos, t_s, amb)
    hint = np.where(
        rng.random(n) < 0.5,
        right + rng.integers(-2, 3, size=n),
        rng.integers(-1, int(table.n_seg.max()), size=n),
    )
    hint = np.clip(hint, -1, table.n_seg[plan_idx] - 1)
    wp_f, d_f, tau_f, seg_f = table.locate(plan_idx, pos, t_s, amb)
    before = dict(table.searches)
    wp_w, d_w, tau_w, seg_w = table.locate(plan_idx, pos, t_s, amb, hint=hint)
    assert table.searches["window"] > before["window"]  # the window path did run
    np.testing.assert_array_equal(seg_w, seg_f)
    np.testing.assert_array_equal(wp_w, wp_f)
    np.testing.assert_array_equal(tau_w, tau_f)
    differs = d_w != d_f
    assert np.all(d_w[differs] > d_f[differs])
    assert np.all(d_w[differs] <= amb[differs])
