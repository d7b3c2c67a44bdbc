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

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.monitoring.loss import separation_ratio
from gcs_utm.model import FloatArray


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
