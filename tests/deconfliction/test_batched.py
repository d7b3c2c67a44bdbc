"""The batched paths of Tactical Deconfliction give exactly what one call per plan gives.

TD scores all alternatives of a UAS in one vectorised pass (``score_many``) and converts all
new plans to WGS84 in one projection call (``local_to_plans``). These tests compare them, bit
for bit, with an independent per-plan implementation: the scoring code as it was before it was
batched (kept here as the oracle), and one frame conversion per plan.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import (
    LocalFence,
    LocalPlan,
    fence_to_local,
    linspace,
    local_to_plans,
)
from gcs_utm.core.deconfliction.scoring import (
    SAMPLE_DT_S,
    Neighbour,
    Score,
    reference,
    sample_times,
    score_many,
)
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import FloatArray, OperationId, Waypoint4D

CFG = DeconflictionConfig()


# ---- the oracle: one plan at a time (the scoring code before batching) ------------------------
def _oracle_segment_distances(
    points: FloatArray, polylines: Sequence[FloatArray]
) -> list[FloatArray]:
    starts = np.concatenate([v[:-1] for v in polylines])
    ab = np.concatenate([v[1:] - v[:-1] for v in polylines])
    ll = np.maximum((ab * ab).sum(axis=1), 1e-12)
    ap = points[:, None, :] - starts[None, :, :]
    u = np.minimum(np.maximum((ap * ab).sum(axis=2) / ll, 0.0), 1.0)
    d = ap - u[:, :, None] * ab[None, :, :]
    d2 = (d * d).sum(axis=2)
    out = []
    k = 0
    for v in polylines:
        m = len(v) - 1
        out.append(np.sqrt(d2[:, k : k + m].min(axis=1)))
        k += m
    return out


def _oracle_prox(x: float, factor: float) -> float:
    return float(np.clip((factor - x) / (factor - 1.0), 0.0, 1.0))


def oracle_score(
    new: LocalPlan,
    old: LocalPlan,
    filed: LocalPlan,
    ov_radius_m: float,
    fences: Sequence[LocalFence],
    neighbours: Sequence[Neighbour],
    priority_weight: float,
    priority_levels: int,
    abandons: bool,
    spherical: bool,
) -> Score:
    config = CFG
    new_xyz = new.xyz()
    new_len = float(np.sqrt(((new_xyz[1:] - new_xyz[:-1]) ** 2).sum(axis=1)).sum())
    extra_d = max(0.0, new_len - old.length_m())
    extra_t = max(0.0, float(new.t[-1] - old.t[-1]))
    span = float(new.t[-1] - new.t[0])
    steps = max(2, int(span / SAMPLE_DT_S) + 1)
    times = np.linspace(float(new.t[0]), float(new.t[-1]), steps)
    pos, _ = new.sample(times)
    seg = np.sqrt(((pos[1:] - pos[:-1]) ** 2).sum(axis=1))
    mid = 0.5 * (pos[1:] + pos[:-1])
    tmid = 0.5 * (times[1:] + times[:-1])
    nm = mid.shape[0]
    probe = np.concatenate([mid, new_xyz])
    lines = [v for v in (old.xyz(), filed.xyz()) if len(v) >= 2]
    dists = _oracle_segment_distances(probe, lines) if lines else []
    offset = 0.0
    if len(old) >= 2:
        offset = float(dists[0][nm:].max())
    elif len(old) == 1:
        offset = float(np.sqrt(((probe[nm:] - old.xyz()[0]) ** 2).sum(axis=1)).max())
    cost = priority_weight * (
        extra_d / config.cost_distance_scale_m
        + extra_t / config.cost_time_scale_s
        + offset / config.cost_offset_scale_m
    )
    cost += config.priority_move_cost * max(0, priority_levels)
    if abandons:
        cost += config.abandon_cost
    inside_m = 0.0
    min_fence = float("inf")
    for f in fences:
        active = np.asarray(f.active_mask(tmid), dtype=bool) & (
            mid[:, 2] >= f.min_alt_amsl_m - ov_radius_m
        )
        active &= mid[:, 2] <= f.max_alt_amsl_m + ov_radius_m
        if not active.any():
            continue
        dist = f.horizontal_distance(mid[active, 0], mid[active, 1])
        inside_m += float(np.sum(seg[active][dist < 0.0]))
        min_fence = min(min_fence, float(dist.min()))
    outside_m = 0.0
    if len(filed) >= 2:
        outside_m = float(np.sum(seg[dists[-1][:nm] > ov_radius_m]))
    min_ratio = float("inf")
    for nb in neighbours:
        other, ok = nb.plan.sample(times)
        if not ok.any():
            continue
        dh = np.hypot(pos[ok, 0] - other[ok, 0], pos[ok, 1] - other[ok, 1])
        dv = np.abs(pos[ok, 2] - other[ok, 2])
        if spherical:
            ratio = np.hypot(dh, dv) / nb.h_min_m
        else:
            ratio = np.maximum(dh / nb.h_min_m, dv / nb.v_min_m)
        min_ratio = min(min_ratio, float(ratio.min()))
    factor = config.risk_proximity_factor
    risk = inside_m / config.risk_length_scale_m + outside_m / config.risk_outside_ov_scale_m
    if np.isfinite(min_fence):
        risk += _oracle_prox(min_fence / max(ov_radius_m, 1e-6), factor)
    if np.isfinite(min_ratio):
        risk += _oracle_prox(min_ratio, factor)
    return Score(
        cost=cost,
        risk=risk,
        extra_distance_m=extra_d,
        extra_time_s=extra_t,
        offset_m=offset,
        inside_fences_m=inside_m,
        outside_ov_m=outside_m,
        min_fence_distance_m=min_fence,
        min_separation_ratio=min_ratio,
    )


# ---- random plans and fences ----------------------------------------------------------------
coord = st.floats(min_value=-600.0, max_value=600.0, allow_nan=False)
alt = st.floats(min_value=40.0, max_value=160.0, allow_nan=False)


@st.composite
def plans(draw: st.DrawFn, min_points: int = 1) -> LocalPlan:
    k = draw(st.integers(min_value=min_points, max_value=6))
    t0 = sc.T0_S + draw(st.floats(min_value=0.0, max_value=30.0))
    # Zero durations are allowed (a hover or an instant vertical leg).
    dts = draw(st.lists(st.floats(min_value=0.0, max_value=60.0), min_size=k - 1, max_size=k - 1))
    t = t0 + np.concatenate([[0.0], np.cumsum(dts)])
    pts = [(draw(coord), draw(coord), draw(alt)) for _ in range(k)]
    a = np.array(pts, dtype=np.float64).reshape(k, 3)
    return LocalPlan(a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy(), t)


@st.composite
def local_fences(draw: st.DrawFn) -> LocalFence:
    e, n = draw(coord), draw(coord)
    lo = draw(st.floats(min_value=0.0, max_value=120.0))
    hi = lo + draw(st.floats(min_value=5.0, max_value=200.0))
    start = draw(st.none() | st.floats(min_value=sc.T0_S, max_value=sc.T0_S + 120.0))
    if draw(st.booleans()):
        g = sc.cylinder(
            "c", e, n, draw(st.floats(min_value=20.0, max_value=200.0)), min_alt_m=lo, max_alt_m=hi
        )
    else:
        w = draw(st.floats(min_value=20.0, max_value=200.0))
        g = sc.polygon(
            "p", [(e - w, n - w), (e + w, n - w), (e, n + w)], min_alt_m=lo, max_alt_m=hi
        )
    f = fence_to_local(g, sc.FRAME)
    if start is None:
        return f
    return LocalFence(
        id=f.id,
        shape=f.shape,
        cylinder=f.cylinder,
        min_alt_amsl_m=f.min_alt_amsl_m,
        max_alt_amsl_m=f.max_alt_amsl_m,
        start_t_s=start,
        end_t_s=start + 90.0,
    )


@settings(max_examples=150, deadline=None)
@given(
    news=st.lists(plans(min_points=2), min_size=1, max_size=5)
    | st.lists(plans(), min_size=1, max_size=3),
    old=plans(),
    filed=plans(),
    fences=st.lists(local_fences(), max_size=3),
    nb_plans=st.lists(plans(), max_size=2),
    data=st.data(),
    spherical=st.booleans(),
    ov=st.floats(min_value=5.0, max_value=40.0),
    levels=st.integers(min_value=0, max_value=3),
)
def test_score_many_equals_scoring_each_plan_alone(
    news: list[LocalPlan],
    old: LocalPlan,
    filed: LocalPlan,
    fences: list[LocalFence],
    nb_plans: list[LocalPlan],
    data: st.DataObject,
    spherical: bool,
    ov: float,
    levels: int,
) -> None:
    applies = [
        np.array(
            data.draw(st.lists(st.booleans(), min_size=len(fences), max_size=len(fences))),
            dtype=bool,
        )
        for _ in news
    ]
    abandons = data.draw(st.lists(st.booleans(), min_size=len(news), max_size=len(news)))
    nbs = [Neighbour(plan=p, h_min_m=50.0, v_min_m=20.0) for p in nb_plans]
    weight = 1.0 + 0.5 * levels
    got = score_many(
        news,
        reference(old, filed, ov, nbs),
        fences=fences,
        applies=applies,
        priority_weight=weight,
        priority_levels=levels,
        abandons=abandons,
        spherical=spherical,
        config=CFG,
    )
    for i, new in enumerate(news):
        mine = [f for f, ok in zip(fences, applies[i], strict=True) if ok]
        want = oracle_score(new, old, filed, ov, mine, nbs, weight, levels, abandons[i], spherical)
        assert dataclasses.replace(got[i], closest=None) == want, i
        # the closest separation in metres is where the ratio is reached
        c = got[i].closest
        if not math.isfinite(want.min_separation_ratio):
            assert c is None
        else:
            assert c is not None
            ratio = (
                math.hypot(c.horizontal_m, c.vertical_m) / c.min_horizontal_m
                if spherical
                else max(c.horizontal_m / c.min_horizontal_m, c.vertical_m / c.min_vertical_m)
            )
            assert ratio == pytest.approx(want.min_separation_ratio, rel=1e-9, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(
    spans=st.lists(
        st.tuples(
            st.floats(min_value=1.6e9, max_value=1.8e9),
            st.floats(min_value=0.0, max_value=900.0),
            st.integers(min_value=2, max_value=400),
        ),
        min_size=1,
        max_size=6,
    )
)
def test_sample_times_is_linspace_per_plan(spans: list[tuple[float, float, int]]) -> None:
    t0 = np.array([a for a, _, _ in spans])
    t1 = np.array([a + d for a, d, _ in spans])
    counts = np.array([c for _, _, c in spans], dtype=np.intp)
    want = np.concatenate([np.linspace(a, b, c) for a, b, c in zip(t0, t1, counts, strict=True)])
    assert np.array_equal(sample_times(t0, t1, counts), want)
    for a, b, c in zip(t0, t1, counts, strict=True):
        assert np.array_equal(linspace(float(a), float(b), int(c)), np.linspace(a, b, c))


def test_local_to_plans_equals_one_conversion_per_plan() -> None:
    snap, _ = sc.scenario_los_2uas()
    bases = [snap.operations[OperationId("A")].plan, snap.operations[OperationId("B")].plan]
    rng = np.random.default_rng(5)
    lps = []
    for k in (2, 5, 1, 7):
        t = sc.T0_S + np.cumsum(rng.uniform(0.0, 30.0, k))
        e, n = rng.uniform(-2000.0, 2000.0, (2, k))
        lps.append(LocalPlan(e, n, rng.uniform(50, 150, k), t))
    plans = local_to_plans(
        lps, bases * 2, sc.FRAME, created_t_s=sc.T0_S, reasons=["a", "b", "c", "d"]
    )
    for lp, base, plan, reason in zip(lps, bases * 2, plans, "abcd", strict=True):
        lat, lon = sc.FRAME.to_wgs84(lp.e, lp.n)
        want = tuple(
            Waypoint4D(lat_deg=float(a), lon_deg=float(o), alt_amsl_m=float(z), t_s=float(t))
            for a, o, z, t in zip(np.atleast_1d(lat), np.atleast_1d(lon), lp.z, lp.t, strict=True)
        )
        assert plan.waypoints == want
        assert plan.operation_id == base.operation_id and plan.version == base.version + 1
        assert plan.reason == reason and plan.created_t_s == sc.T0_S


def test_scenarios_sharing_one_prepared_problem_equal_scenarios_on_their_own() -> None:
    """TD prepares the scenario-independent part of the cord problem once per decision and
    runs every scenario on it: each result equals the scenario run alone, and running them
    leaves the shared arrays untouched."""
    from gcs_utm.core.deconfliction import cords as cd
    from gcs_utm.core.deconfliction.geometry import plan_to_local

    snap, _ = sc.scenario_chain_5uas()
    lps = [plan_to_local(o.plan, sc.FRAME) for o in snap.operations.values()]
    grid = sc.T0_S + np.arange(0, 201, 2.0)
    minima = np.full((5, 5, 2), [50.0, 20.0])
    for spherical in (False, True):
        problem = cd.prepare(lps, grid, minima, spherical=spherical, margin_fraction=0.15)
        frozen = [a.copy() for a in (problem.samples.base, problem.sep0, problem.target)]
        scenarios = [
            ([axis] * 5, [0] * 5, [True] * 5) for axis in (cd.Axis.VERTICAL, cd.Axis.LATERAL)
        ]
        for k in range(2):
            for axis in (cd.Axis.VERTICAL, cd.Axis.LATERAL):
                for sign in (1, -1):
                    scenarios.append(
                        (
                            [axis] * 5,
                            [sign if j == k else 0 for j in range(5)],
                            [j == k for j in range(5)],
                        )
                    )
        for axes, signs, mobile in scenarios:
            cords = [
                cd.Cord(
                    plan=lp,
                    axis=axes[i] if mobile[i] else cd.Axis.NONE,
                    sign=signs[i],
                    mobility=1.0 / (1 + i % 3) if mobile[i] else 0.0,
                    slope_m_per_step=3.6 if axes[i] == cd.Axis.VERTICAL else 11.5,
                    max_offset_m=120.0,
                    min_alt_amsl_m=0.0,
                    max_alt_amsl_m=500.0,
                )
                for i, lp in enumerate(lps)
            ]
            kw = {"spherical": spherical, "margin_fraction": 0.15, "max_iterations": 60}
            shared = cd.resolve(cords, grid, minima, problem=problem, **kw)  # type: ignore[arg-type]
            alone = cd.resolve(cords, grid, minima, **kw)  # type: ignore[arg-type]
            if alone is None:
                assert shared is None
                continue
            assert shared is not None
            assert shared.signs == alone.signs and shared.iterations == alone.iterations
            assert np.array_equal(shared.displacement_m, alone.displacement_m)
        for a, b in zip(frozen, (problem.samples.base, problem.sep0, problem.target), strict=True):
            assert np.array_equal(a, b)


def _oracle_first_clear_delay(
    td: object,
    lp: LocalPlan,
    now: float,
    grid_t: FloatArray,
    others: list[LocalPlan],
    h: float,
    v: float,
) -> float | None:
    """The delay search as it was: every delayed position interpolated, (D, T, 3) layout."""
    cfg = td.config  # type: ignore[attr-defined]
    steps = int(cfg.max_delay_s // cfg.delay_step_s)
    delays = cfg.delay_step_s * np.arange(1, steps + 1, dtype=np.float64)
    tt = np.maximum(grid_t[None, :] - delays[:, None], now)
    valid = tt <= lp.t[-1]
    pos = np.stack([np.interp(tt, lp.t, c) for c in (lp.e, lp.n, lp.z)], axis=-1)
    clear = np.ones(delays.shape[0], dtype=bool)
    for o in others:
        q, ok = o.sample(grid_t)
        m = valid & ok[None, :]
        dh = np.hypot(pos[..., 0] - q[None, :, 0], pos[..., 1] - q[None, :, 1])
        dv = np.abs(pos[..., 2] - q[None, :, 2])
        ratio = np.maximum(dh / h, dv / v)
        clear &= ~((ratio < 1.0 + cfg.separation_margin_fraction) & m).any(axis=1)
    idx = np.flatnonzero(clear)
    return float(delays[idx[0]]) if idx.size else None


@settings(max_examples=60, deadline=None)
@given(
    now_frac=st.sampled_from([0.0, 0.3, 0.123456789]),
    step=st.sampled_from([5.0, 2.5, 1.0, 0.7]),
    angle=st.floats(min_value=0.0, max_value=180.0),
    dn=st.floats(min_value=-200.0, max_value=200.0),
    t_other=st.floats(min_value=-60.0, max_value=60.0),
)
def test_delay_search_equals_interpolating_every_delayed_position(
    now_frac: float, step: float, angle: float, dn: float, t_other: float
) -> None:
    """The delay search gathers the plan sampled once on its grid when every delayed time is
    a grid time (checked value by value), and interpolates otherwise: the smallest clear
    delay is the same as interpolating every delayed position."""
    from gcs_utm.core.deconfliction.timing import Screen, first_clear_delay

    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(delay_step_s=step), MonitoringConfig())
    now = sc.T0_S + now_frac
    lp = LocalPlan(
        np.array([-1000.0, 1000.0]), np.zeros(2), np.full(2, 100.0), np.array([now, now + 200.0])
    )
    a = np.radians(angle)
    other = LocalPlan(
        np.array([-1000.0 * np.cos(a), 1000.0 * np.cos(a)]),
        np.array([dn - 1000.0 * np.sin(a), dn + 1000.0 * np.sin(a)]),
        np.full(2, 100.0),
        np.array([now + t_other, now + t_other + 200.0]),
    )
    grid_t = np.arange(now, now + 200.0 / 0.6 + 1.0, 1.0)
    q, ok = other.sample(grid_t)
    screen = Screen(q[:, 0].copy(), q[:, 1].copy(), q[:, 2].copy(), ok, 50.0, 20.0)
    cfg = td.config
    delays = cfg.delay_step_s * np.arange(
        1, int(cfg.max_delay_s // cfg.delay_step_s) + 1, dtype=np.float64
    )
    got = first_clear_delay(
        lp, now, grid_t, [screen], delays, cfg.separation_margin_fraction, False
    )
    assert got == _oracle_first_clear_delay(td, lp, now, grid_t, [other], 50.0, 20.0)


def _oracle_left_normals(pos: FloatArray) -> FloatArray:
    k = pos.shape[0]
    d = np.zeros((k, 2))
    if k > 1:
        step = pos[1:, :2] - pos[:-1, :2]
        d[:-1] = step
        d[-1] = step[-1]
    norm = np.hypot(d[:, 0], d[:, 1])
    good = norm > 1e-6
    if not good.any():
        return np.tile(np.array([0.0, 1.0]), (k, 1))
    idx = np.where(good, np.arange(k), 0)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(good))
    idx[:first] = first
    u = d[idx] / norm[idx, None]
    return np.column_stack([-u[:, 1], u[:, 0]])


def _oracle_deformed(
    op: object,
    cfg: DeconflictionConfig,
    lp: LocalPlan,
    grid: FloatArray,
    d: FloatArray,
    axis: object,
    sign: int,
) -> LocalPlan:
    """TD's deformation on (N, 3) rows: horizontal speed up to the cruise speed (or the
    filed pace) times the factor and within the envelope's maximum, climbs at the envelope's
    climb rate and descents at its descent rate (or the filed pace where steeper)."""
    from gcs_utm.core.deconfliction import cords as cd

    cruise = op.cruise_speed_mps  # type: ignore[attr-defined]
    env = op.performance()  # type: ignore[attr-defined]
    d1 = d[1:] - d[:-1]
    kinks = grid[1:-1][np.abs(d1[1:] - d1[:-1]) > 1e-9]
    inside = (kinks >= lp.t[0]) & (kinks <= lp.t[-1])
    times = np.union1d(kinks[inside], lp.t)
    base, _ = lp.sample(times)
    disp = np.interp(times, grid, d)
    if axis is cd.Axis.VERTICAL:
        xyz = base.copy()
        xyz[:, 2] += sign * disp
    else:
        xyz = cd.apply(base, _oracle_left_normals(base), axis, sign, disp)
    dt = times[1:] - times[:-1]
    ob = base[1:] - base[:-1]
    safe_dt = np.maximum(dt, 1e-9)
    f = cfg.max_speed_factor
    pace = np.hypot(ob[:, 0], ob[:, 1]) / safe_dt
    speed = np.minimum(np.maximum(cruise, pace) * f, np.maximum(env.max_speed_mps, pace))
    up = np.maximum(env.climb_rate_mps, np.maximum(ob[:, 2], 0.0) / safe_dt)
    down = np.maximum(env.descent_rate_mps, np.maximum(-ob[:, 2], 0.0) / safe_dt)
    dd = xyz[1:] - xyz[:-1]
    vertical = np.where(dd[:, 2] > 0.0, dd[:, 2] / up, -dd[:, 2] / down)
    need = np.maximum(dt, np.maximum(np.hypot(dd[:, 0], dd[:, 1]) / speed, vertical))
    t = np.empty(len(times))
    t[0] = times[0]
    np.cumsum(need, out=t[1:])
    t[1:] += times[0]
    goal = np.array([lp.e[-1], lp.n[-1], lp.z[-1]])
    off = xyz[-1] - goal
    if float(np.abs(off).max()) > 1e-3:
        rate = env.descent_rate_mps if off[2] > 0.0 else env.climb_rate_mps
        dt_back = max(float(np.hypot(off[0], off[1])) / cruise, abs(float(off[2])) / rate)
        xyz = np.vstack([xyz, goal])
        t = np.append(t, t[-1] + dt_back)
    return LocalPlan(xyz[:, 0], xyz[:, 1], xyz[:, 2], t)


@settings(max_examples=80, deadline=None)
@given(lp=plans(), data=st.data(), vertical=st.booleans(), sign=st.sampled_from([1, -1]))
def test_deformation_and_normals_equal_the_row_wise_code(
    lp: LocalPlan, data: st.DataObject, vertical: bool, sign: int
) -> None:
    """TD's deformation (one array per coordinate) equals the (N, 3) row-wise code it
    replaced, for any plan (hovers and vertical legs included) and any slope-limited
    displacement profile, laterally and vertically; so do the cords' left normals."""
    from gcs_utm.core.deconfliction import cords as cd
    from gcs_utm.core.deconfliction.context import deform
    from gcs_utm.core.deconfliction.deform import concave_hull

    pos = lp.xyz()
    assert np.array_equal(cd.left_normals(pos), _oracle_left_normals(pos))
    snap, _ = sc.scenario_los_2uas()
    op = snap.operations[OperationId("A")]
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MonitoringConfig())
    grid: FloatArray = float(lp.t[0]) + 2.0 * np.arange(60, dtype=np.float64)
    demand = np.zeros(60)
    for _ in range(data.draw(st.integers(min_value=0, max_value=3))):
        demand[data.draw(st.integers(min_value=1, max_value=59))] = data.draw(
            st.floats(min_value=0.0, max_value=80.0)
        )
    d = np.minimum(cd.envelope(demand, 3.6), 3.6 * np.arange(60))
    axis = cd.Axis.VERTICAL if vertical else cd.Axis.LATERAL
    got = deform(op, lp, grid, d, axis, sign, td.config)
    # the deformation flies the profile's unimodal hull (tested on its own in test_td)
    want = _oracle_deformed(op, td.config, lp, grid, concave_hull(d), axis, sign)
    for c in ("e", "n", "z", "t"):
        assert np.array_equal(getattr(got, c), getattr(want, c)), c
