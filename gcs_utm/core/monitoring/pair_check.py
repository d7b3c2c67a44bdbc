"""The exact check of many plan pairs at once (the strategic check's last step).

What a pair's result is (the definition; ``tests/monitoring/strategic_oracle.py`` computes it
pair by pair): over the pair's common time span [t0, t1], the sample times are both plans'
waypoint times in the span, t0, t1 and the ``step_s`` grid ``np.arange(t0, t1, step_s)``;
both plans' positions at those times (``np.interp``); the segment kernel
(:func:`~.geometry.segment_separation`) on every sub-segment between consecutive samples; the
pair is in conflict when any sub-segment is, with the first loss, the closest approach (the
first sub-segment of the smallest distance) and the smallest horizontal and vertical distances
over all sub-segments. A pair whose bounding boxes are farther apart than the minima is not
checked.

How it is computed without a Python step per pair or a kernel call per grid sample (a dense
airspace has ~100,000 candidate pairs of ~600 samples each):

1. Screen: between consecutive waypoint times of either plan both move linearly, so the kernel
   on these few coarse segments, with the minima grown by a millimetre, finds every pair that
   can be in conflict (the sub-segments differ from the coarse motion only by rounding, about
   1e-10 m). The others are not in conflict.
2. Windows: for a remaining pair, only the sub-segments whose figures can be a minimum are
   evaluated: around the first loss (between the first loss with the minima grown and with
   them shrunk by the millimetre), and where the 3D, horizontal or vertical distance is within
   a margin of its smallest coarse value (the distance is convex along each coarse segment,
   so that is an interval of it). Over a coarse segment where both plans keep their altitude,
   every sub-segment has the same vertical distance: it is taken from the waypoints directly.
   A pair whose loss is within the millimetre of the minima, a plan that is not strictly
   increasing in time or a short span is evaluated in full, and so is every pair of a call
   with few samples in all (one plan against a few, as a resolution is verified).
3. The samples of those windows (the same grid values ``np.arange`` gives, the same waypoint
   times), positions by ``np.interp`` per plan, the kernel, and segmented reductions per pair
   that keep the first index of a minimum, as ``np.argmin`` does.

The figures are therefore bit for bit those of evaluating every sub-segment;
``tests/monitoring/test_pair_check.py`` checks that against the pair-by-pair definition.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.geometry import (
    FloatArray,
    relative_loss_interval,
    segment_separation,
)

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

_LOSS_MARGIN_M = 1e-3  # the screen's minima grow (and shrink) by this, plus 1e-9 of the scale
_DIST_MARGIN = 1e-8  # squared-distance margin of the windows, relative to the pair's scale^2
_TIME_MARGIN_S = 1e-3  # windows grow by this on each side (sample times are ~1e-7 s apart)
_FULL_BELOW = 16  # grid samples: a shorter span is evaluated in full
_SCREEN_ABOVE = 20_000  # grid samples of all pairs: fewer are all evaluated in full
_BATCH = 400_000  # samples per vectorised pass (memory: a few dozen arrays of it)


@dataclass(frozen=True, slots=True)
class PairFigures:
    """Per pair (input order): ``conflict`` and, where it is set, the figures of
    :class:`~.strategic.PlanConflict` (NaN elsewhere)."""

    conflict: BoolArray
    first_loss_t_s: FloatArray
    closest_t_s: FloatArray
    min_distance_m: FloatArray
    min_horizontal_m: FloatArray
    min_vertical_m: FloatArray


@dataclass(frozen=True, slots=True)
class _Plans:
    """All plans' waypoints in one table: plan i is rows off[i] .. off[i] + k[i]."""

    t: FloatArray
    xyz: FloatArray  # (W, 3)
    off: IntArray
    k: IntArray
    regular: BoolArray  # >= 2 waypoints, strictly increasing times
    lo: FloatArray  # (N, 3) bounding box
    hi: FloatArray

    @staticmethod
    def of(local: Sequence[FloatArray]) -> _Plans:
        k = np.array([len(p) for p in local], np.int64)
        table = np.concatenate(local) if local else np.empty((0, 4))
        off = np.cumsum(k) - k
        t = table[:, 3]
        step_ok = np.ones(len(t), bool)
        step_ok[:-1] = t[1:] > t[:-1]
        last = off + k - 1
        step_ok[last] = True  # no step after a plan's last waypoint
        bad = np.add.reduceat((~step_ok).astype(np.int64), off) if len(t) else np.zeros(0, np.int64)
        return _Plans(
            t=t,
            xyz=table[:, :3],
            off=off,
            k=k,
            regular=(k >= 2) & (bad == 0),
            lo=np.minimum.reduceat(table[:, :3], off, axis=0),
            hi=np.maximum.reduceat(table[:, :3], off, axis=0),
        )


def check_pairs(
    local: Sequence[FloatArray],
    ia: IntArray,
    ib: IntArray,
    min_h_m: FloatArray,
    min_v_m: FloatArray,
    *,
    spherical: bool,
    step_s: float,
) -> PairFigures:
    """The exact check of the pairs (``local[ia[p]]``, ``local[ib[p]]``), with the pairs'
    minima (see the module doc)."""
    n = len(ia)
    out = PairFigures(np.zeros(n, bool), *(np.full(n, np.nan) for _ in range(5)))
    if n == 0:
        return out
    plans = _Plans.of(local)
    ia, ib = np.asarray(ia, np.int64), np.asarray(ib, np.int64)
    mh, mv = np.asarray(min_h_m, np.float64), np.asarray(min_v_m, np.float64)
    t0 = np.maximum(plans.t[plans.off[ia]], plans.t[plans.off[ib]])
    t1 = np.minimum(
        plans.t[plans.off[ia] + plans.k[ia] - 1], plans.t[plans.off[ib] + plans.k[ib] - 1]
    )
    live = (t0 <= t1) & ~_boxes_apart(plans, ia, ib, (mh, mv), spherical=spherical)
    grid_n, delta = _grid(t0, t1, step_s)
    screen = live & plans.regular[ia] & plans.regular[ib] & (grid_n >= _FULL_BELOW)
    if grid_n[live].sum() < _SCREEN_ABOVE:
        screen[:] = False  # few samples in all: the screen would cost more than it saves
    pairs = _Pairs(ia, ib, t0, t1, mh, mv, grid_n, delta, step_s)
    win_p, win_lo, win_hi, vconst = _screened_windows(
        plans, pairs, np.flatnonzero(screen), spherical=spherical
    )
    full = np.flatnonzero(live & ~screen)
    win_p = np.concatenate([win_p, full])
    win_lo = np.concatenate([win_lo, t0[full]])
    win_hi = np.concatenate([win_hi, t1[full]])
    _evaluate(plans, pairs, (win_p, win_lo, win_hi), vconst=vconst, spherical=spherical, out=out)
    return out


@dataclass(frozen=True, slots=True)
class _Pairs:
    ia: IntArray
    ib: IntArray
    t0: FloatArray
    t1: FloatArray
    mh: FloatArray
    mv: FloatArray
    grid_n: IntArray  # samples of np.arange(t0, t1, step_s)
    delta: FloatArray  # its spacing as np.arange computes it
    step_s: float


def _boxes_apart(
    plans: _Plans,
    ia: IntArray,
    ib: IntArray,
    minima: tuple[FloatArray, FloatArray],
    *,
    spherical: bool,
) -> BoolArray:
    """The cheap reject: the plans' bounding boxes are farther apart than the minima."""
    mh, mv = minima
    gap = np.maximum(np.maximum(plans.lo[ia] - plans.hi[ib], plans.lo[ib] - plans.hi[ia]), 0.0)
    if spherical:
        out: BoolArray = np.sqrt((gap[:, 0] ** 2 + gap[:, 1] ** 2) + gap[:, 2] ** 2) >= mh
        return out
    far: BoolArray = (np.hypot(gap[:, 0], gap[:, 1]) >= mh) | (gap[:, 2] >= mv)
    return far


def _grid(t0: FloatArray, t1: FloatArray, step_s: float) -> tuple[IntArray, FloatArray]:
    """Length and spacing of ``np.arange(t0, t1, step_s)`` per pair: element k is t0 for
    k = 0, t0 + step_s for k = 1, t0 + k * ((t0 + step_s) - t0) after (numpy's fill)."""
    if step_s <= 0:
        return np.zeros(len(t0), np.int64), np.ones(len(t0))
    span = np.where(t1 > t0, t1 - t0, 0.0)
    n = np.ceil(span / step_s).astype(np.int64)
    return n, (t0 + step_s) - t0


def _grid_at(pairs: _Pairs, p: IntArray, k: IntArray) -> FloatArray:
    t0 = pairs.t0[p]
    out: FloatArray = np.where(k == 1, t0 + pairs.step_s, t0 + k * pairs.delta[p])
    return out


# ------------------------------------------------------------------------------------------
# 1-2. Screen and windows on the coarse segments


@dataclass(frozen=True, slots=True)
class _Coarse:
    """Coarse segments (rows): pair ``p``, time span [lo, hi], relative position ``d0`` at lo
    and motion ``v`` over the row, both plans' altitude constant over it (``zconst``, with the
    exact vertical distance ``dz``)."""

    p: IntArray
    lo: FloatArray
    hi: FloatArray
    d0: FloatArray  # (R, 3)
    v: FloatArray
    zconst: BoolArray
    dz: FloatArray


def _coarse(plans: _Plans, pairs: _Pairs, sel: IntArray) -> _Coarse:
    """Every (segment of a, segment of b) of the pairs ``sel`` that overlap in time within
    the common span: between consecutive waypoint times of either plan."""
    na = plans.k[pairs.ia[sel]] - 1
    nb = plans.k[pairs.ib[sel]] - 1
    rows = na * nb
    p = np.repeat(sel, rows)
    r = np.arange(rows.sum()) - np.repeat(np.cumsum(rows) - rows, rows)
    ja = plans.off[pairs.ia[p]] + r // np.repeat(nb, rows)
    jb = plans.off[pairs.ib[p]] + r % np.repeat(nb, rows)
    t = plans.t
    lo = np.maximum(np.maximum(t[ja], t[jb]), pairs.t0[p])
    hi = np.minimum(np.minimum(t[ja + 1], t[jb + 1]), pairs.t1[p])
    keep = lo < hi
    p, ja, jb, lo, hi = p[keep], ja[keep], jb[keep], lo[keep], hi[keep]
    a_lo, a_hi = _along(plans, ja, lo), _along(plans, ja, hi)
    b_lo, b_hi = _along(plans, jb, lo), _along(plans, jb, hi)
    d0 = a_lo - b_lo
    z = plans.xyz[:, 2]
    zconst = (z[ja] == z[ja + 1]) & (z[jb] == z[jb + 1])
    return _Coarse(p, lo, hi, d0, (a_hi - b_hi) - d0, zconst, np.abs(z[ja] - z[jb]))


def _along(plans: _Plans, j: IntArray, t: FloatArray) -> FloatArray:
    """Position on waypoint segment j (rows j, j + 1) at time t (accurate, not np.interp's
    rounding: the screen's margins cover the difference)."""
    t_a, t_b = plans.t[j], plans.t[j + 1]
    frac = ((t - t_a) / (t_b - t_a))[:, None]
    out: FloatArray = plans.xyz[j] + frac * (plans.xyz[j + 1] - plans.xyz[j])
    return out


def _screened_windows(
    plans: _Plans, pairs: _Pairs, sel: IntArray, *, spherical: bool
) -> tuple[IntArray, FloatArray, FloatArray, FloatArray]:
    """Windows (pair, t_lo, t_hi) to evaluate for the screened pairs ``sel``, and per pair
    the smallest vertical distance of its constant-altitude coarse segments (inf if none)."""
    n = len(pairs.t0)
    vconst = np.full(n, np.inf)
    if len(sel) == 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0), vconst
    c = _coarse(plans, pairs, sel)
    scale2 = np.zeros(n)
    np.maximum.at(scale2, c.p, (c.d0**2).sum(axis=1) + (c.v**2).sum(axis=1))
    margin = _LOSS_MARGIN_M + 1e-9 * np.sqrt(scale2[c.p])
    mh, mv = pairs.mh[c.p], pairs.mv[c.p]
    first_in = _first_loss(c, (mh + margin, mv + margin), spherical=spherical, n=n)
    shrunk_h, shrunk_v = np.maximum(mh - margin, 0.0), np.maximum(mv - margin, 0.0)
    first_out = _first_loss(c, (shrunk_h, shrunk_v), spherical=spherical, n=n)
    survive = np.isfinite(first_in)
    clear = survive & np.isfinite(first_out)
    border = survive & ~clear
    win = [(border.nonzero()[0], pairs.t0[border], pairs.t1[border])]
    cl = clear.nonzero()[0]
    win.append((cl, first_in[cl] - _TIME_MARGIN_S, first_out[cl] + _TIME_MARGIN_S))
    rows = clear[c.p]
    m2 = _DIST_MARGIN * scale2 + 1e-6
    for axes in ((0, 1, 2), (0, 1)):
        win.append(_near_min(c, rows, axes, m2, None))
    zc = rows & c.zconst
    np.minimum.at(vconst, c.p[zc], c.dz[zc])
    win.append(_near_min(c, rows, (2,), m2, vconst))
    vconst[~clear] = np.inf
    return (
        np.concatenate([w[0] for w in win]).astype(np.int64),
        np.concatenate([w[1] for w in win]),
        np.concatenate([w[2] for w in win]),
        vconst,
    )


def _first_loss(
    c: _Coarse, minima: tuple[FloatArray, FloatArray], *, spherical: bool, n: int
) -> FloatArray:
    """Per pair the first time of loss with these minima over its coarse rows (inf: none)."""
    d0 = (c.d0[:, 0], c.d0[:, 1], c.d0[:, 2])
    v = (c.v[:, 0], c.v[:, 1], c.v[:, 2])
    lo, hi = relative_loss_interval(
        d0, v, min_h_m=minima[0], min_v_m=minima[1], spherical=spherical
    )
    loss = lo < hi
    out = np.full(n, np.inf)
    np.minimum.at(out, c.p[loss], c.lo[loss] + lo[loss] * (c.hi[loss] - c.lo[loss]))
    return out


def _near_min(
    c: _Coarse,
    rows: BoolArray,
    axes: tuple[int, ...],
    m2: FloatArray,
    vconst: FloatArray | None,
) -> tuple[IntArray, FloatArray, FloatArray]:
    """Windows where the distance over ``axes`` is within the margin ``m2`` (squared, per
    pair) of the pair's smallest coarse value: an interval of each row (convex). With
    ``vconst`` (the vertical distance), rows of constant altitude take part in the smallest
    value (``vconst`` holds it) but need no window."""
    # rows of constant altitude need no vertical window: their exact value joins the best
    use = rows & ~c.zconst if vconst is not None else rows
    d0 = c.d0[use][:, axes]
    v = c.v[use][:, axes]
    p = c.p[use]
    a = (v**2).sum(axis=1)
    b = 2.0 * (d0 * v).sum(axis=1)
    cc = (d0**2).sum(axis=1)
    moving = a > 0.0
    s_star = np.where(moving, np.clip(-b / np.where(moving, 2.0 * a, 1.0), 0.0, 1.0), 0.0)
    best = ((d0 + s_star[:, None] * v) ** 2).sum(axis=1)
    pair_best = np.full(len(m2), np.inf) if vconst is None else vconst**2
    np.minimum.at(pair_best, p, best)
    limit = pair_best[p] + m2[p]
    flat = a <= 1e-12 * (cc + 1.0)  # no usable curvature: the whole row, if it gets close
    centre = -b / np.where(flat, 1.0, 2.0 * a)
    vertex = cc - b * b / np.where(flat, 1.0, 4.0 * a)
    half = np.sqrt(np.maximum(limit - vertex, 0.0) / np.where(flat, 1.0, a))
    s_lo = np.where(flat, 0.0, np.clip(centre - half, 0.0, 1.0))
    s_hi = np.where(flat, 1.0, np.clip(centre + half, 0.0, 1.0))
    take = (best <= limit) & (s_lo <= s_hi)
    lo, hi = c.lo[use], c.hi[use]
    span = hi - lo
    return (
        p[take],
        (lo + s_lo * span)[take] - _TIME_MARGIN_S,
        (lo + s_hi * span)[take] + _TIME_MARGIN_S,
    )


# ------------------------------------------------------------------------------------------
# 3. Samples of the windows, the kernel, reductions per pair


def _evaluate(
    plans: _Plans,
    pairs: _Pairs,
    windows: tuple[IntArray, FloatArray, FloatArray],
    *,
    vconst: FloatArray,
    spherical: bool,
    out: PairFigures,
) -> None:
    k_lo, k_hi, wp = _ranges(pairs, *windows)
    if len(wp) == 0:
        return
    # batches of whole pairs, about _BATCH samples each
    starts = np.flatnonzero(np.concatenate([[True], wp[1:] != wp[:-1]]))
    per_pair = np.add.reduceat(k_hi - k_lo + 1, starts)
    batch = (np.cumsum(per_pair) - per_pair) // _BATCH
    cuts = starts[np.flatnonzero(np.diff(batch)) + 1]
    edges = np.concatenate([[0], cuts, [len(wp)]])
    for a, b in zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True):
        ranges = (wp[a:b], k_lo[a:b], k_hi[a:b])
        _evaluate_batch(plans, pairs, ranges, vconst=vconst, spherical=spherical, out=out)


def _ranges(
    pairs: _Pairs, p: IntArray, w_lo: FloatArray, w_hi: FloatArray
) -> tuple[IntArray, IntArray, IntArray]:
    """Windows as ranges of grid indices (index grid_n stands for t1), merged per pair where
    they overlap or touch, sorted by pair then start."""
    n_grid = pairs.grid_n[p]
    t0 = pairs.t0[p]
    w_lo = np.clip(w_lo, t0, pairs.t1[p])
    w_hi = np.clip(w_hi, t0, pairs.t1[p])
    d = pairs.delta[p]
    k_lo = np.clip(np.floor((w_lo - t0) / d) - 1, 0, n_grid).astype(np.int64)
    k_hi = np.clip(np.ceil((w_hi - t0) / d) + 1, 0, n_grid).astype(np.int64)
    k_hi[w_hi >= pairs.t1[p]] = n_grid[w_hi >= pairs.t1[p]]
    order = np.lexsort((k_lo, p))
    p, k_lo, k_hi = p[order], k_lo[order], k_hi[order]
    if len(p) == 0:
        return k_lo, k_hi, p
    # running end within each pair: a range starts anew past the previous ends
    big = int(pairs.grid_n.max()) + 2
    run_end = np.maximum.accumulate(p * big + k_hi) - p * big
    new = np.ones(len(p), bool)
    new[1:] = (p[1:] != p[:-1]) | (k_lo[1:] > run_end[:-1])
    first = np.flatnonzero(new)
    hi = np.maximum.reduceat(k_hi, first)
    return k_lo[first], hi, p[first]


def _evaluate_batch(
    plans: _Plans,
    pairs: _Pairs,
    ranges: tuple[IntArray, IntArray, IntArray],
    *,
    vconst: FloatArray,
    spherical: bool,
    out: PairFigures,
) -> None:
    wp, k_lo, k_hi = ranges
    rng, t = _samples(plans, pairs, wp, k_lo, k_hi)
    # sub-segments: consecutive samples of one range (a range of one sample: zero length)
    i0 = np.flatnonzero(rng[1:] == rng[:-1])
    i1 = i0 + 1
    single = np.bincount(rng, minlength=len(wp)) == 1
    if single.any():  # t0 == t1: the span is one instant
        lone = np.flatnonzero(single[rng])
        i0 = np.sort(np.concatenate([i0, lone]))
        i1 = np.where(np.isin(i0, lone), i0, i0 + 1)
    p = wp[rng[i0]]
    both = _positions(plans, np.concatenate([pairs.ia[wp[rng]], pairs.ib[wp[rng]]]), np.tile(t, 2))
    pa, pb = both[: len(t)], both[len(t) :]
    res = segment_separation(
        pa[i0],
        pa[i1],
        pb[i0],
        pb[i1],
        min_h_m=pairs.mh[p],
        min_v_m=pairs.mv[p],
        spherical=spherical,
    )
    ts, dt = t[i0], t[i1] - t[i0]
    starts = np.flatnonzero(np.concatenate([[True], p[1:] != p[:-1]]))
    pid = p[starts]
    loss = np.logical_or.reduceat(res.loss, starts)
    if not loss.any():
        return
    first_s = np.where(res.loss, res.first_loss_s, 0.0)
    key = np.where(res.loss, ts + first_s * dt, np.inf)
    k = _first_min(key, starts)
    c = _first_min(res.cpa_m, starts)
    sel = pid[loss]
    out.conflict[sel] = True
    k, c = k[loss], c[loss]
    out.first_loss_t_s[sel] = ts[k] + res.first_loss_s[k] * dt[k]
    out.closest_t_s[sel] = ts[c] + res.cpa_s[c] * dt[c]
    out.min_distance_m[sel] = res.cpa_m[c]
    out.min_horizontal_m[sel] = np.minimum.reduceat(res.min_h_m, starts)[loss]
    out.min_vertical_m[sel] = np.minimum(np.minimum.reduceat(res.min_v_m, starts), vconst[pid])[
        loss
    ]


def _first_min(values: FloatArray, starts: IntArray) -> IntArray:
    """Per segment (``starts``) the first index of its smallest value (``np.argmin``)."""
    counts = np.diff(np.append(starts, len(values)))
    seg_of = np.repeat(np.arange(len(starts)), counts)
    hits = np.flatnonzero(values == np.minimum.reduceat(values, starts)[seg_of])
    first = np.ones(len(hits), bool)
    first[1:] = seg_of[hits[1:]] != seg_of[hits[:-1]]
    out: IntArray = hits[first]
    return out


def _samples(
    plans: _Plans, pairs: _Pairs, wp: IntArray, k_lo: IntArray, k_hi: IntArray
) -> tuple[IntArray, FloatArray]:
    """The sample times of each range, sorted and unique: grid values k_lo..k_hi (t1 for
    index grid_n) and the pair's waypoint times, t0 and t1 between its first and last."""
    n_grid = pairs.grid_n[wp]
    g_hi = np.minimum(k_hi, n_grid - 1)
    count = np.maximum(g_hi - k_lo + 1, 0)
    r_g = np.repeat(np.arange(len(wp)), count)
    k = np.repeat(k_lo, count) + (
        np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    )
    g = _grid_at(pairs, wp[r_g], k)
    t0, t1 = pairs.t0[wp], pairs.t1[wp]
    last = np.maximum(n_grid - 1, 0)
    a_t = np.where(k_lo == 0, t0, _grid_at(pairs, wp, np.minimum(k_lo, last)))
    b_t = np.where(k_hi >= n_grid, t1, _grid_at(pairs, wp, np.minimum(k_hi, last)))
    ka, kb = plans.k[pairs.ia[wp]], plans.k[pairs.ib[wp]]
    nk = ka + kb + 2
    r_w = np.repeat(np.arange(len(wp)), nk)
    j = np.arange(nk.sum()) - np.repeat(np.cumsum(nk) - nk, nk)
    ka_r = np.repeat(ka, nk)
    row = np.where(
        j < ka_r,
        plans.off[pairs.ia[wp[r_w]]] + j,
        plans.off[pairs.ib[wp[r_w]]] + (j - ka_r),
    )
    kb_r = np.repeat(kb, nk)
    w = np.where(
        j < ka_r + kb_r,
        plans.t[np.minimum(row, len(plans.t) - 1)],
        np.where(j == ka_r + kb_r, t0[r_w], t1[r_w]),
    )
    w_in = (w >= np.maximum(a_t, t0)[r_w]) & (w <= np.minimum(b_t, t1)[r_w])
    w_in &= (w >= t0[r_w]) & (w <= t1[r_w])
    g_in = g <= t1[r_g]
    rng = np.concatenate([r_g[g_in], r_w[w_in]])
    t = np.concatenate([g[g_in], w[w_in]])
    order = np.lexsort((t, rng))
    rng, t = rng[order], t[order]
    keep = np.ones(len(t), bool)
    keep[1:] = (rng[1:] != rng[:-1]) | (t[1:] != t[:-1])
    return rng[keep], t[keep]


def _positions(plans: _Plans, plan: IntArray, t: FloatArray) -> FloatArray:
    """(len(t), 3) positions of plan[i] at t[i], by ``np.interp`` per plan (its values)."""
    order = np.argsort(plan, kind="stable")
    ps, xs = plan[order], t[order]
    cuts = np.flatnonzero(ps[1:] != ps[:-1]) + 1
    firsts = np.concatenate([[0], cuts]).tolist()
    ends = np.append(cuts, len(ps)).tolist()
    res = np.empty((3, len(t)))
    axes = [np.ascontiguousarray(plans.xyz[:, k]) for k in range(3)]
    for lo, hi, q in zip(firsts, ends, ps[firsts].tolist(), strict=True):
        w0, w1 = int(plans.off[q]), int(plans.off[q] + plans.k[q])
        tt, x = plans.t[w0:w1], xs[lo:hi]
        for k in range(3):
            res[k, lo:hi] = np.interp(x, tt, axes[k][w0:w1])
    out = np.empty((len(t), 3))
    out[order] = res.T
    return out
