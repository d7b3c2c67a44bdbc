"""Loss-of-separation detection on predicted 4D trajectories (paper §4.4, 4D grid).

Input: ``points`` (N, S, 4) of east_m, north_m, alt_amsl_m, t_s, all rows on the SAME time
steps (one prediction at one ``t_s``), and ``ov_m`` (N,) operational-volume radii (0 for
tracks without a volume). A pair (a, b) loses separation when, at one instant, their
horizontal distance < min_h AND vertical distance < min_v (``MonitoringConfig.
effective_minima``; sphere mode: 3D distance < the safety distance). Between samples both
move linearly, and the exact kernel :func:`segment_separation` decides.

Three detectors give identical results (they share ``_evaluate``):
- :func:`detect_los_bruteforce`: every pair, every segment. The oracle.
- :func:`detect_los_allpairs`: every pair of per-window swept boxes, then the kernel.
- :func:`detect_los_grid`: the 4D grid. Each trajectory is cut into time windows of
  ``grid_dt_s``; each window's swept box (all its samples, so all its segments), grown by
  max(min/2, own volume) per axis, is entered into every (dx, dy, dz, window) cell it
  touches. Two trajectories can lose separation in a window only if their grown boxes
  overlap, and then they share a cell: no conflict is ever missed. Only pairs sharing a cell
  are confirmed with the kernel.
:func:`detect_los` picks all-pairs below ``config.allpairs_below`` trajectories.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.geometry import (
    FloatArray,
    Windows,
    relative_approach,
    relative_loss_interval,
    relative_separation,
    window_extents,
)
from gcs_utm.core.monitoring.loss import minima_arrays

IntArray = npt.NDArray[np.int64]

# Segment-pairs evaluated per vectorised chunk: bounds memory (~20 arrays of this size).
_CHUNK = 100_000


class PredictionError(ValueError):
    """Prediction rows that do not share one time base."""


class SeparationLoss(NamedTuple):
    """A predicted loss of separation between rows ``a`` < ``b`` of the prediction (an
    immutable record; a named tuple because a dense cycle builds tens of thousands)."""

    a: int
    b: int
    first_loss_t_s: float
    closest_t_s: float
    min_distance_m: float
    min_horizontal_m: float
    min_vertical_m: float


def _segments(points: FloatArray) -> FloatArray:
    """(N, S', 4) with S' >= 2: a single sample becomes one zero-length segment."""
    if points.shape[1] == 1:
        return np.concatenate([points, points], axis=1)
    return points


def _check_time_base(points: FloatArray) -> None:
    if len(points) > 1:
        spread = float(np.max(np.abs(points[:, :, 3] - points[:1, :, 3])))
        if spread > 1e-6:
            raise PredictionError(f"prediction rows have different times (spread {spread} s)")


def _minima(
    ov_a: FloatArray, ov_b: FloatArray, config: MonitoringConfig
) -> tuple[FloatArray, FloatArray]:
    return minima_arrays(config, ov_a, ov_b)  # the shared definition (monitoring.loss)


Planes = tuple[FloatArray, FloatArray, FloatArray]


def _planes(points: FloatArray) -> Planes:
    """East, north, up of ``points`` (N, S, 4) as three contiguous (N, S) arrays: the kernels
    gather rows and take differences along S far faster than through the (N, S, 4) stride."""
    return (
        np.ascontiguousarray(points[:, :, 0]),
        np.ascontiguousarray(points[:, :, 1]),
        np.ascontiguousarray(points[:, :, 2]),
    )


@dataclass(frozen=True, slots=True)
class _Samples:
    """The prediction (N, S, 4) as one (N * S, 4) view, row after row, from which the
    samples of any (row, window) are gathered on demand: only candidate windows are ever
    copied, never the whole prediction."""

    flat: FloatArray  # (N * S, 4)
    n: int
    s: int

    @staticmethod
    def of(points: FloatArray) -> _Samples:
        n, s, _ = points.shape
        return _Samples(points.reshape(n * s, 4), n, s)

    def window(self, rows: IntArray, win: IntArray, w: int) -> FloatArray:
        """Samples j * w .. j * w + w of window j = ``win`` of each row of ``rows``:
        (C, w + 1, 4). A short last window runs into the next row (or repeats the very last
        sample): the segments beyond a row's end must be masked."""
        start = rows * self.s + win * w
        idx = np.minimum(start[:, None] + np.arange(w + 1), self.n * self.s - 1)
        out: FloatArray = self.flat[idx]
        return out


def _evaluate(
    pl_a: Planes,
    pl_b: Planes,
    ia: IntArray,
    ib: IntArray,
    *,
    times: FloatArray,
    min_h: FloatArray,
    min_v: FloatArray,
    spherical: bool,
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Full-horizon kernel for C row pairs (rows ``ia`` of ``pl_a``, ``ib`` of ``pl_b``) on the
    common sample times ``times`` (S,); minima (C,). Returns (loss (C,), stats (C, 5) =
    first_loss_t, closest_t, min_distance, min_horizontal, min_vertical)."""
    c_n, s_n = len(ia), len(times) - 1
    loss = np.zeros(c_n, bool)
    stats = np.empty((c_n, 5))
    step = max(1, _CHUNK // max(s_n, 1))
    t0 = times[:-1]  # s
    dt = times[1:] - t0  # s
    for i in range(0, c_n, step):
        ra = ia[i : i + step]
        rb = ib[i : i + step]
        rel = [pa[ra] - pb[rb] for pa, pb in zip(pl_a, pl_b, strict=True)]  # m, (c, S)
        seg = relative_separation(
            (rel[0][:, :-1], rel[1][:, :-1], rel[2][:, :-1]),
            (
                rel[0][:, 1:] - rel[0][:, :-1],
                rel[1][:, 1:] - rel[1][:, :-1],
                rel[2][:, 1:] - rel[2][:, :-1],
            ),
            min_h_m=min_h[i : i + step, None],
            min_v_m=min_v[i : i + step, None],
            spherical=spherical,
        )
        loss[i : i + step] = seg.loss.any(axis=1)
        first = np.where(seg.loss, seg.first_loss_s, 0.0)  # avoids inf * 0 on still segments
        stats[i : i + step, 0] = np.min(np.where(seg.loss, t0 + first * dt, np.inf), axis=1)
        k = np.argmin(seg.cpa_m, axis=1)
        r = np.arange(len(ra))
        stats[i : i + step, 1] = t0[k] + seg.cpa_s[r, k] * dt[k]
        stats[i : i + step, 2] = seg.cpa_m[r, k]
        stats[i : i + step, 3] = seg.min_h_m.min(axis=1)
        stats[i : i + step, 4] = seg.min_v_m.min(axis=1)
    return loss, stats


def _confirm(
    points: FloatArray,
    ov_m: FloatArray,
    ia: IntArray,
    ib: IntArray,
    config: MonitoringConfig,
    *,
    planes: Planes | None = None,
) -> list[SeparationLoss]:
    """Run the kernel on candidate pairs (ia < ib) and return the confirmed losses."""
    if len(ia) == 0:
        return []
    pl = _planes(points) if planes is None else planes
    mh, mv = _minima(ov_m[ia], ov_m[ib], config)
    loss, stats = _evaluate(
        pl, pl, ia, ib, times=points[0, :, 3], min_h=mh, min_v=mv, spherical=config.spherical
    )
    return [
        SeparationLoss(
            a=int(ia[i]),
            b=int(ib[i]),
            first_loss_t_s=float(stats[i, 0]),
            closest_t_s=float(stats[i, 1]),
            min_distance_m=float(stats[i, 2]),
            min_horizontal_m=float(stats[i, 3]),
            min_vertical_m=float(stats[i, 4]),
        )
        for i in np.nonzero(loss)[0]
    ]


def detect_los_bruteforce(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig
) -> list[SeparationLoss]:
    """Every pair on every segment with the exact kernel: the oracle (O(N^2 S))."""
    points = _segments(np.asarray(points, np.float64))
    _check_time_base(points)
    ia, ib = np.triu_indices(len(points), k=1)
    return _confirm(
        points, np.asarray(ov_m, np.float64), ia.astype(np.int64), ib.astype(np.int64), config
    )


def _unique(x: IntArray) -> IntArray:
    """Sorted unique values (sort based: faster than numpy's hash-based unique here)."""
    x = np.sort(x)
    if len(x) == 0:
        return x
    keep = np.empty(len(x), bool)
    keep[0] = True
    np.not_equal(x[1:], x[:-1], out=keep[1:])
    return x[keep]


def window_steps(points: FloatArray, config: MonitoringConfig) -> int:
    """Segments per grid time window: ``grid_dt_s`` in whole prediction steps (>= 1)."""
    n_seg = points.shape[1] - 1
    step_s = float(points[0, 1, 3] - points[0, 0, 3]) if len(points) else 1.0
    w = max(1, round(config.grid_dt_s / step_s)) if step_s > 0 else n_seg
    return int(max(1, min(w, n_seg)))


def _window_boxes(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig, windows: Windows | None
) -> tuple[FloatArray, FloatArray, int]:
    """Grown swept boxes per (row, window): lo, hi (N, nw, 3) in metres, and W steps/window."""
    windows = _matching(points, window_steps(points, config), windows)
    if config.spherical:
        half_h = half_v = config.safety_distance_m / 2.0
    else:
        half_h = config.separation_horizontal_m / 2.0
        half_v = config.separation_vertical_m / 2.0
    rh = np.maximum(half_h, ov_m)[:, None]  # m, r_a + r_b >= the pair's minimum
    rv = np.maximum(half_v, ov_m)[:, None]
    grow = np.stack([rh, rh, rv], axis=-1)  # (N, 1, 3)
    return windows.lo[:, :, :3] - grow, windows.hi[:, :, :3] + grow, windows.w


def _matching(points: FloatArray, w: int, windows: Windows | None) -> Windows:
    """``windows`` if they are the bounds of ``points`` at ``w`` steps, else computed."""
    nw = -(-(points.shape[1] - 1) // w)
    if windows is None or windows.w != w or windows.lo.shape[:2] != (len(points), nw):
        return window_extents(points, w)
    return windows


def _box_overlap(
    lo: FloatArray, hi: FloatArray, ia: IntArray, ib: IntArray
) -> npt.NDArray[np.bool_]:
    out: npt.NDArray[np.bool_] = np.all((lo[ia] <= hi[ib]) & (lo[ib] <= hi[ia]), axis=-1)
    return out


def detect_los_allpairs(
    points: FloatArray,
    ov_m: FloatArray,
    config: MonitoringConfig,
    windows: Windows | None = None,
) -> list[SeparationLoss]:
    """All pairs of grown window boxes, then the kernel on pairs whose boxes overlap in some
    window. Faster than the grid for small N (no hashing or sorting)."""
    points = _segments(np.asarray(points, np.float64))
    _check_time_base(points)
    ov = np.asarray(ov_m, np.float64)
    if len(points) < 2:
        return []
    windows = _matching(points, window_steps(points, config), windows)
    lo, hi, w = _window_boxes(points, ov, config, windows)
    ia, ib = np.triu_indices(len(points), k=1)
    step = _CHUNK // max(lo.shape[1], 1) + 1
    out_p: list[IntArray] = []
    out_w: list[IntArray] = []
    for i in range(0, len(ia), step):
        p, j = np.nonzero(_box_overlap(lo, hi, ia[i : i + step], ib[i : i + step]))
        out_p.append(p + i)
        out_w.append(j)
    pi = np.concatenate(out_p)
    return _windowed_losses(
        points,
        ov,
        ia[pi].astype(np.int64),
        ib[pi].astype(np.int64),
        np.concatenate(out_w).astype(np.int64),
        w=w,
        lo=windows.lo,
        hi=windows.hi,
        config=config,
    )


def _window_rel(
    samples: _Samples, ia: IntArray, ib: IntArray, win: IntArray, *, w: int
) -> tuple[Planes, Planes, npt.NDArray[np.bool_] | None]:
    """Relative position at the start of each of the W segments of window ``win`` of pairs
    (ia, ib), and the relative motion per segment (per axis, (C, W)); plus the validity mask
    of the segments (None: all valid; the last window may be shorter). The floats are
    exactly those of the full-horizon kernel."""
    n_seg = samples.s - 1
    ga = samples.window(ia, win, w)
    gb = samples.window(ib, win, w)
    rel = [ga[:, :, k] - gb[:, :, k] for k in range(3)]  # m, (C, W + 1)
    d0 = (rel[0][:, :-1], rel[1][:, :-1], rel[2][:, :-1])
    v = (
        rel[0][:, 1:] - rel[0][:, :-1],
        rel[1][:, 1:] - rel[1][:, :-1],
        rel[2][:, 1:] - rel[2][:, :-1],
    )
    valid = None if n_seg % w == 0 else (win * w)[:, None] + np.arange(w) < n_seg
    return d0, v, valid


def _screen(
    samples: _Samples,
    times: FloatArray,
    ia: IntArray,
    ib: IntArray,
    win: IntArray,
    *,
    w: int,
    min_h: FloatArray,
    min_v: FloatArray,
    spherical: bool,
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Exact loss test on the W segments of each candidate (pair, window): (loss somewhere
    in the window (C,), time of first loss in the window (C,), +inf without loss)."""
    t0 = times[:-1]  # s
    dt = times[1:] - t0  # s
    hit = np.zeros(len(ia), bool)
    first_t = np.full(len(ia), np.inf)
    step = max(1, _CHUNK // w)
    for i in range(0, len(ia), step):
        sl = slice(i, i + step)
        d0, v, valid = _window_rel(samples, ia[sl], ib[sl], win[sl], w=w)
        lo, hi = relative_loss_interval(
            d0, v, min_h_m=min_h[sl, None], min_v_m=min_v[sl, None], spherical=spherical
        )
        loss = lo < hi
        if valid is not None:
            loss &= valid
        h = loss.any(axis=1)
        hit[sl] = h
        if h.any():
            sk = np.minimum(win[sl][h, None] * w + np.arange(w), len(t0) - 1)  # segment
            first = np.where(loss[h], t0[sk] + lo[h] * dt[sk], np.inf)  # as in ``_evaluate``
            first_t[i + np.nonzero(h)[0]] = first.min(axis=1)
    return hit, first_t


def _approach(
    samples: _Samples, times: FloatArray, ia: IntArray, ib: IntArray, win: IntArray, *, w: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Closest approach within each (pair, window): 3D distance, its time (the first segment
    on a tie) and the minimum horizontal distance, each (C,)."""
    t0 = times[:-1]  # s
    dt = times[1:] - t0  # s
    cpa_m = np.empty(len(ia))
    cpa_t = np.empty(len(ia))
    min_h = np.empty(len(ia))
    step = max(1, _CHUNK // w)
    for i in range(0, len(ia), step):
        sl = slice(i, i + step)
        d0, v, valid = _window_rel(samples, ia[sl], ib[sl], win[sl], w=w)
        s_c, d_c, h_c, _ = relative_approach(d0, v)
        if valid is not None:
            d_c = np.where(valid, d_c, np.inf)
            h_c = np.where(valid, h_c, np.inf)
        k = np.argmin(d_c, axis=1)
        r = np.arange(len(k))
        sk = win[sl] * w + k  # segment of the closest approach (always a valid one)
        cpa_m[sl] = d_c[r, k]
        cpa_t[sl] = t0[sk] + s_c[r, k] * dt[sk]  # as in ``_evaluate``
        min_h[sl] = h_c.min(axis=1)
    return cpa_m, cpa_t, min_h


def _min_vertical(points: FloatArray, ia: IntArray, ib: IntArray) -> FloatArray:
    """Minimum vertical distance over the whole horizon per pair (as ``relative_approach``:
    0 where the relative altitude changes sign, else the smaller end)."""
    out = np.empty(len(ia))
    step = max(1, _CHUNK // points.shape[1])
    for i in range(0, len(ia), step):
        sl = slice(i, i + step)
        rz = points[ia[sl], :, 2] - points[ib[sl], :, 2]  # m, (c, S)
        z0 = rz[:, :-1]
        z1 = z0 + (rz[:, 1:] - z0)  # the kernel's z0 + v, bit for bit
        seg = np.where(z0 * z1 <= 0.0, 0.0, np.minimum(np.abs(z0), np.abs(z1)))
        out[sl] = seg.min(axis=1)
    return out


def _windowed_losses(
    points: FloatArray,
    ov_m: FloatArray,
    ia: IntArray,
    ib: IntArray,
    win: IntArray,
    *,
    w: int,
    lo: FloatArray,
    hi: FloatArray,
    config: MonitoringConfig,
) -> list[SeparationLoss]:
    """Exact losses from candidate (pair a < b, window) triples that include every window in
    which a pair can lose separation; ``lo``, ``hi`` (N, nw, >=3) are the UNGROWN window
    bounds. Gives the oracle's figures (``_evaluate`` over the full horizon) at a fraction of
    its cost:

    1. loss test on the candidate windows -> the pairs in loss and their first loss (a loss
       can only occur in a candidate window);
    2. closest approach on the windows in loss -> upper bounds U (3D) and Uh (horizontal);
    3. every other window of those pairs whose box gap (a lower bound of the distance in the
       window) is within U or Uh (plus a rounding margin) is evaluated too; the rest cannot
       hold the minimum. The minimum vertical distance comes from one cheap pass over z.
    """
    n = len(points)
    if len(ia) == 0:
        return []
    samples = _Samples.of(points)
    times = points[0, :, 3]
    mh, mv = _minima(ov_m[ia], ov_m[ib], config)
    hit, first_t = _screen(
        samples, times, ia, ib, win, w=w, min_h=mh, min_v=mv, spherical=config.spherical
    )
    if not hit.any():
        return []
    code = ia[hit] * n + ib[hit]
    hw = win[hit]
    hf = first_t[hit]
    order = np.lexsort((hw, code))
    code, hw, hf = code[order], hw[order], hf[order]
    new = np.empty(len(code), bool)
    new[0] = True
    np.not_equal(code[1:], code[:-1], out=new[1:])
    starts = np.nonzero(new)[0]
    pair_of = np.cumsum(new) - 1  # pair index of each hit window
    pa = code[starts] // n
    pb = code[starts] % n
    first = np.minimum.reduceat(hf, starts)
    # 2. closest approach where the pairs lose separation
    cm, ct, ch = _approach(samples, times, pa[pair_of], pb[pair_of], hw, w=w)
    u3 = np.minimum.reduceat(cm, starts)
    uh = np.minimum.reduceat(ch, starts)
    # 3. other windows that may hold a closer approach (box gap as the lower bound)
    gap = np.maximum(
        np.maximum(lo[pa, :, :3] - hi[pb, :, :3], lo[pb, :, :3] - hi[pa, :, :3]), 0.0
    )  # m, (P, nw, 3)
    span = np.maximum(hi[pa, :, :3], hi[pb, :, :3]) - np.minimum(lo[pa, :, :3], lo[pb, :, :3])
    tol = 1e-3 + 1e-6 * span.sum(axis=2)  # m, far above the kernels' rounding
    g2h = gap[:, :, 0] ** 2 + gap[:, :, 1] ** 2
    need = g2h + gap[:, :, 2] ** 2 <= (u3[:, None] + tol) ** 2
    need |= g2h <= (uh[:, None] + tol) ** 2
    need[pair_of, hw] = False  # already evaluated
    xp, xw = np.nonzero(need)
    if len(xp):
        cm2, ct2, ch2 = _approach(samples, times, pa[xp], pb[xp], xw, w=w)
        pair_of = np.concatenate([pair_of, xp])
        hw = np.concatenate([hw, xw])
        cm = np.concatenate([cm, cm2])
        ct = np.concatenate([ct, ct2])
        ch = np.concatenate([ch, ch2])
    order = np.lexsort((hw, cm, pair_of))  # per pair: smallest distance, earliest window
    pair_of, cm, ct, ch = pair_of[order], cm[order], ct[order], ch[order]
    head = np.empty(len(pair_of), bool)
    head[0] = True
    np.not_equal(pair_of[1:], pair_of[:-1], out=head[1:])
    starts = np.nonzero(head)[0]
    min_h = np.minimum.reduceat(ch, starts)
    min_v = _min_vertical(points, pa, pb)
    cm, ct = cm[starts], ct[starts]
    fields = (pa, pb, first, ct, cm, min_h, min_v)
    return list(map(SeparationLoss, *(f.tolist() for f in fields)))


def grid_candidates(
    points: FloatArray,
    ov_m: FloatArray,
    config: MonitoringConfig,
    windows: Windows | None = None,
) -> tuple[IntArray, IntArray, IntArray, int]:
    """Candidate (row a < row b, window) triples whose grown window boxes overlap, found by
    sharing a 4D cell; also returns the window length W in steps.

    Per time window, each grown box is entered in every (dx, dy, dz) cell it touches; the
    entries are packed as ``cell << bits | row`` and sorted (a plain sort of integers is far
    faster than an argsort), so rows sharing a cell end up adjacent."""
    n = len(points)
    lo, hi, w = _window_boxes(points, ov_m, config, windows)
    nw = lo.shape[1]
    # A cell at least as big as the median box keeps most boxes within 2 cells per axis.
    cell = np.maximum(
        np.array([config.grid_dx_m, config.grid_dy_m, config.grid_dz_m]),
        np.median((hi - lo).reshape(-1, 3), axis=0),
    )
    # (window, axis, row): every per-window, per-axis bound is one contiguous vector.
    lo_t = np.ascontiguousarray(lo.transpose(1, 2, 0))
    hi_t = np.ascontiguousarray(hi.transpose(1, 2, 0))
    bits = max(1, int(n - 1).bit_length())
    out_a: list[IntArray] = []
    out_b: list[IntArray] = []
    out_w: list[IntArray] = []
    for j in range(nw):
        lo_j = lo_t[j]
        hi_j = hi_t[j]
        a, b = _same_cell_pairs(lo_j, hi_j, cell, bits)
        if len(a) == 0:
            continue
        code = _unique(a * n + b)  # a box meets another in up to 8 cells
        a = code // n
        b = code % n
        keep = (lo_j[0][a] <= hi_j[0][b]) & (lo_j[0][b] <= hi_j[0][a])
        for k in (1, 2):
            keep &= (lo_j[k][a] <= hi_j[k][b]) & (lo_j[k][b] <= hi_j[k][a])
        out_a.append(a[keep])
        out_b.append(b[keep])
        out_w.append(np.full(int(keep.sum()), j, np.int64))
    if not out_a:
        empty = np.empty(0, np.int64)
        return empty, empty, empty, w
    return np.concatenate(out_a), np.concatenate(out_b), np.concatenate(out_w), w


def _same_cell_pairs(
    lo: FloatArray, hi: FloatArray, cell: FloatArray, bits: int
) -> tuple[IntArray, IntArray]:
    """Row pairs (a < b, with repeats) whose boxes lo, hi (3, N) touch a common cell."""
    i0 = [np.floor(lo[k] / cell[k]).astype(np.int64) for k in range(3)]
    i1 = [np.floor(hi[k] / cell[k]).astype(np.int64) for k in range(3)]
    for k in range(3):
        base = i0[k].min()
        i0[k] -= base
        i1[k] -= base
    sx, sy, sz = (i1[k] - i0[k] + 1 for k in range(3))  # cells per axis
    count = sx * sy * sz
    row = np.repeat(np.arange(len(count), dtype=np.int64), count)
    k = np.arange(len(row), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    sxr = sx[row]
    sxy = sxr * sy[row]
    cx = i0[0][row] + k % sxr
    cy = i0[1][row] + (k % sxy) // sxr
    cz = i0[2][row] + k // sxy
    wx = int(i1[0].max()) + 1
    wy = int(i1[1].max()) + 1
    wz = int(i1[2].max()) + 1
    if math.log2(wx) + math.log2(wy) + math.log2(wz) + bits < 62:
        packed = np.sort((((cz * wy + cy) * wx + cx) << bits) | row)
        key = packed >> bits
        rows = packed & ((1 << bits) - 1)
    else:  # a huge airspace in tiny cells: keys too wide to pack, sort the pairs instead
        key = (cz * wy + cy) * wx + cx if wx * wy * wz < 2**62 else _dense(cx, cy, cz)
        order = np.lexsort((row, key))
        key = key[order]
        rows = row[order]
    pa: list[IntArray] = []
    pb: list[IntArray] = []
    d = 1
    while d < len(key):
        same = key[d:] == key[:-d]  # entries d apart in one cell (rows ascending within it)
        if not same.any():
            break
        pa.append(rows[:-d][same])
        pb.append(rows[d:][same])
        d += 1
    if not pa:
        empty = np.empty(0, np.int64)
        return empty, empty
    return np.concatenate(pa), np.concatenate(pb)


def _dense(cx: IntArray, cy: IntArray, cz: IntArray) -> IntArray:
    """Cell coordinates -> dense integer ids (for ranges too wide to multiply out)."""
    _, inv = np.unique(np.column_stack([cx, cy, cz]), axis=0, return_inverse=True)
    out: IntArray = inv.ravel().astype(np.int64)
    return out


def detect_los_grid(
    points: FloatArray,
    ov_m: FloatArray,
    config: MonitoringConfig,
    windows: Windows | None = None,
) -> list[SeparationLoss]:
    """The 4D grid detector (see module doc): candidates sharing a cell, a loss screen on the
    candidate windows, then the closest approach on the windows that can hold it
    (``_windowed_losses``)."""
    points = _segments(np.asarray(points, np.float64))
    _check_time_base(points)
    ov = np.asarray(ov_m, np.float64)
    if len(points) < 2:
        return []
    w = window_steps(points, config)
    windows = _matching(points, w, windows)
    ia, ib, win, w = grid_candidates(points, ov, config, windows)
    return _windowed_losses(
        points, ov, ia, ib, win, w=w, lo=windows.lo, hi=windows.hi, config=config
    )


def detect_los(
    points: FloatArray,
    ov_m: FloatArray,
    config: MonitoringConfig,
    windows: Windows | None = None,
) -> list[SeparationLoss]:
    """All-pairs below ``config.allpairs_below`` rows, the 4D grid above. ``windows``: the
    prediction's :func:`window_extents` at :func:`window_steps` (computed if not given or
    not matching), so a caller can share them with the geofence check."""
    if len(points) < config.allpairs_below:
        return detect_los_allpairs(points, ov_m, config, windows)
    return detect_los_grid(points, ov_m, config, windows)


def detect_pairs_between(
    pa: FloatArray,
    pb: FloatArray,
    min_h_m: float,
    min_v_m: float,
    *,
    spherical: bool = False,
) -> list[tuple[int, int, FloatArray]]:
    """Every row of ``pa`` against every row of ``pb`` (e.g. UAS x intruders) with fixed
    minima. Returns (i, j, stats) for losses; stats as in ``SeparationLoss`` order."""
    pa = _segments(np.asarray(pa, np.float64))
    pb = _segments(np.asarray(pb, np.float64))
    if len(pa) == 0 or len(pb) == 0:
        return []
    # Prefilter: whole-horizon boxes, b's grown by the minima (a superset of the losses).
    grow = np.array([min_h_m, min_h_m, min_h_m if spherical else min_v_m])  # m
    lo_a, hi_a = pa[:, :, :3].min(axis=1), pa[:, :, :3].max(axis=1)
    lo_b, hi_b = pb[:, :, :3].min(axis=1) - grow, pb[:, :, :3].max(axis=1) + grow
    near = np.all((lo_a[:, None] <= hi_b[None]) & (lo_b[None] <= hi_a[:, None]), axis=2)
    ia, ib = np.nonzero(near)
    mh = np.full(len(ia), float(min_h_m))
    mv = np.full(len(ia), float(min_v_m))
    loss, stats = _evaluate(
        _planes(pa), _planes(pb), ia, ib, times=pa[0, :, 3], min_h=mh, min_v=mv, spherical=spherical
    )
    return [(int(ia[i]), int(ib[i]), stats[i]) for i in np.nonzero(loss)[0]]
