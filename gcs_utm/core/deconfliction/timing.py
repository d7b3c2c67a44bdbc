"""Timing alternatives of Tactical Deconfliction: hold in place then fly the plan later
(only for a vehicle that can hover), or fly the plan slower. Fast screens on a 1 s grid
against the other plans; Monitoring verifies the candidate that passes.

Separation here is the shared definition (:mod:`gcs_utm.core.monitoring.loss`): a candidate
passes when its separation ratio to every screened plan stays at or above 1 + margin.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from gcs_utm.core.deconfliction.context import Candidate, Context, Problem
from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.monitoring.loss import separation_ratio
from gcs_utm.model import FloatArray, Maneuver, Operation


@dataclass(frozen=True, slots=True, eq=False)
class Screen:
    """Another plan sampled on the timing search's grid (one array per coordinate), its
    validity there and the pair's effective minima."""

    e: FloatArray
    n: FloatArray
    z: FloatArray
    ok: npt.NDArray[np.bool_]
    h_min_m: float
    v_min_m: float


def first_clear_delay(  # noqa: PLR0917 - one call site, positional like the math
    lp: LocalPlan,
    start_t_s: float,
    grid_t: FloatArray,
    screens: Sequence[Screen],
    delays: FloatArray,
    margin_fraction: float,
    spherical: bool,
) -> float | None:
    """The smallest of ``delays`` after which holding at the plan's start and then flying it
    keeps (1 + margin) times the minima from every screened plan; all delays at once."""
    if delays.shape[0] == 0:
        return None
    tt = np.maximum(grid_t[None, :] - delays[:, None], start_t_s)  # (D, T): plan time flown
    valid = tt <= lp.t[-1]
    # Positions at the plan times flown, one (D, T) array per coordinate. When every plan
    # time is itself a grid time (a delay that is a whole number of grid steps, checked
    # value by value), they are the plan sampled once on the grid, gathered; otherwise
    # interpolated.
    shift = np.rint(delays / (grid_t[1] - grid_t[0]) if grid_t.shape[0] > 1 else delays)
    idx = np.maximum(np.arange(grid_t.shape[0])[None, :] - shift.astype(np.intp)[:, None], 0)
    if np.array_equal(grid_t[idx], tt):
        pe, pn, pz = (np.interp(grid_t, lp.t, c)[idx] for c in (lp.e, lp.n, lp.z))
    else:
        pe, pn, pz = (np.interp(tt, lp.t, c) for c in (lp.e, lp.n, lp.z))
    scale = 1.0 + margin_fraction
    clear = np.ones(delays.shape[0], dtype=bool)
    for sc in screens:
        m = valid & sc.ok[None, :]
        dh = np.hypot(pe - sc.e[None, :], pn - sc.n[None, :])
        ratio = separation_ratio(
            dh, pz - sc.z[None, :], sc.h_min_m, sc.v_min_m, spherical=spherical
        )
        clear &= ~((ratio < scale) & m).any(axis=1)
    idx_clear = np.flatnonzero(clear)
    return float(delays[idx_clear[0]]) if idx_clear.size else None


def clear_of(
    cand: LocalPlan,
    grid_t: FloatArray,
    screens: Sequence[Screen],
    margin_fraction: float,
    spherical: bool,
) -> bool:
    """Fast screen of a timing candidate on the grid: every other plan at least (1 + margin)
    times the pair's minima away."""
    pos, mine = cand.sample(grid_t)
    scale = 1.0 + margin_fraction
    for sc in screens:
        m = sc.ok & mine
        if not m.any():
            continue
        dh = np.hypot(pos[m, 0] - sc.e[m], pos[m, 1] - sc.n[m])
        ratio = separation_ratio(
            dh, pos[m, 2] - sc.z[m], sc.h_min_m, sc.v_min_m, spherical=spherical
        )
        if float(ratio.min()) < scale:
            return False
    return True


def timing_candidates(
    ctx: Context, op: Operation, pb: Problem, rigid: Sequence[Operation]
) -> list[Candidate]:
    """The smallest delay (hold at the start point, then the same plan later: only for a
    vehicle that can hover) and the mildest slow-down that separate ``op`` from every
    other plan, if any, as candidates for its alternatives."""
    cfg = ctx.config
    lp = pb.local[op.id]
    t0 = float(lp.t[0])
    others = list(rigid) + list(pb.outsiders)
    slowest = min([f for f in cfg.slowdown_factors if 0.0 < f < 1.0] or [1.0])
    span = float(lp.t[-1] - t0)
    grid_t = np.arange(t0, t0 + max(span / slowest, span + cfg.max_delay_s) + 1.0, 1.0)
    screens = []
    for o in others:
        q, ok = ctx.local_plan(o.plan).sample(grid_t)
        h, v = ctx.pair_minima(op, o)
        screens.append(Screen(q[:, 0].copy(), q[:, 1].copy(), q[:, 2].copy(), ok, h, v))
    margin = cfg.separation_margin_fraction
    spherical = ctx.monitoring.spherical
    out: list[Candidate] = []

    def queue(man: Maneuver, cand: LocalPlan, detail: str) -> None:
        out.append(
            ctx.candidate(
                op,
                man,
                cand,
                lp,
                geofences=pb.geofences,
                fences=pb.fences,
                outsiders=others,
                lowest_priority=pb.lowest,
                detail=detail,
                dest=pb.out[op.id],
            )
        )

    steps = int(cfg.max_delay_s // cfg.delay_step_s)
    delays = cfg.delay_step_s * np.arange(1, max(steps, 0) + 1, dtype=np.float64)
    if not op.performance().can_hover:
        delays = delays[:0]  # a fixed wing cannot stop in place
    delay = first_clear_delay(lp, t0, grid_t, screens, delays, margin, spherical)
    if delay is not None:
        t = np.concatenate([[t0, t0 + delay], lp.t[1:] + delay])
        e = np.concatenate([[lp.e[0]], lp.e])
        n = np.concatenate([[lp.n[0]], lp.n])
        z = np.concatenate([[lp.z[0]], lp.z])
        queue(Maneuver.DELAY, LocalPlan(e, n, z, t), f"hold {delay:.0f} s, then the plan")
    for factor in cfg.slowdown_factors:
        if not 0.0 < factor < 1.0:
            continue
        cand = LocalPlan(lp.e, lp.n, lp.z, t0 + (lp.t - t0) / factor)
        if clear_of(cand, grid_t, screens, margin, spherical):
            queue(Maneuver.SPEED_CHANGE, cand, f"fly the plan at {factor:.0%} of its speed")
            break
    return out
