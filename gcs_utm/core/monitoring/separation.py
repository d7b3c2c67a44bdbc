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

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.geometry import FloatArray, segment_loss, segment_separation

IntArray = npt.NDArray[np.int64]

# Segment-pairs evaluated per vectorised chunk: bounds memory (~20 arrays of this size).
_CHUNK = 400_000


class PredictionError(ValueError):
    """Prediction rows that do not share one time base."""


@dataclass(frozen=True, slots=True, kw_only=True)
class SeparationLoss:
    """A predicted loss of separation between rows ``a`` < ``b`` of the prediction."""

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
    floor = ov_a + ov_b  # m
    if config.spherical:
        s = np.maximum(config.safety_distance_m, floor)
        return s, s
    return (
        np.maximum(config.separation_horizontal_m, floor),
        np.maximum(config.separation_vertical_m, floor),
    )


def _evaluate(
    pa: FloatArray,
    pb: FloatArray,
    min_h: FloatArray,
    min_v: FloatArray,
    spherical: bool,
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Full-horizon kernel for C row pairs: pa, pb (C, S, 4); minima (C,). Returns (loss (C,),
    stats (C, 5) = first_loss_t, closest_t, min_distance, min_horizontal, min_vertical)."""
    c_n, s_n = pa.shape[0], pa.shape[1] - 1
    loss = np.zeros(c_n, bool)
    stats = np.empty((c_n, 5))
    step = max(1, _CHUNK // max(s_n, 1))
    for i in range(0, c_n, step):
        a = pa[i : i + step]
        b = pb[i : i + step]
        seg = segment_separation(
            a[:, :-1],
            a[:, 1:],
            b[:, :-1],
            b[:, 1:],
            min_h_m=min_h[i : i + step, None],
            min_v_m=min_v[i : i + step, None],
            spherical=spherical,
        )
        t0 = a[:, :-1, 3]  # s
        dt = a[:, 1:, 3] - t0  # s
        loss[i : i + step] = seg.loss.any(axis=1)
        first = np.where(seg.loss, seg.first_loss_s, 0.0)  # avoids inf * 0 on still segments
        stats[i : i + step, 0] = np.min(np.where(seg.loss, t0 + first * dt, np.inf), axis=1)
        k = np.argmin(seg.cpa_m, axis=1)
        r = np.arange(len(a))
        stats[i : i + step, 1] = t0[r, k] + seg.cpa_s[r, k] * dt[r, k]
        stats[i : i + step, 2] = seg.cpa_m[r, k]
        stats[i : i + step, 3] = seg.min_h_m.min(axis=1)
        stats[i : i + step, 4] = seg.min_v_m.min(axis=1)
    return loss, stats


def _confirm(
    points: FloatArray, ov_m: FloatArray, ia: IntArray, ib: IntArray, config: MonitoringConfig
) -> list[SeparationLoss]:
    """Run the kernel on candidate pairs (ia < ib) and return the confirmed losses."""
    if len(ia) == 0:
        return []
    mh, mv = _minima(ov_m[ia], ov_m[ib], config)
    loss, stats = _evaluate(points[ia], points[ib], mh, mv, config.spherical)
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


def _window_boxes(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig
) -> tuple[FloatArray, FloatArray, int]:
    """Grown swept boxes per (row, window): lo, hi (N, nw, 3) in metres, and W steps/window."""
    n, s_pts = points.shape[0], points.shape[1]
    n_seg = s_pts - 1
    step_s = float(points[0, 1, 3] - points[0, 0, 3]) if n else 1.0
    w = max(1, round(config.grid_dt_s / step_s)) if step_s > 0 else n_seg
    w = min(w, n_seg)
    nw = math.ceil(n_seg / w)
    lo = np.empty((n, nw, 3))
    hi = np.empty((n, nw, 3))
    for k in range(3):  # one contiguous (N, S) plane per axis: reductions stay cache-friendly
        x = np.ascontiguousarray(points[:, :, k])  # m
        pad = nw * w + 1 - s_pts
        if pad > 0:  # repeat the last sample: adds no position to the last window's box
            x = np.concatenate([x, np.repeat(x[:, -1:], pad, axis=1)], axis=1)
        body = x[:, : nw * w].reshape(n, nw, w)
        ends = x[:, w::w][:, :nw]  # the closing sample of each window
        lo[:, :, k] = np.minimum(body.min(axis=2), ends)  # m
        hi[:, :, k] = np.maximum(body.max(axis=2), ends)  # m
    if config.spherical:
        half_h = half_v = config.safety_distance_m / 2.0
    else:
        half_h = config.separation_horizontal_m / 2.0
        half_v = config.separation_vertical_m / 2.0
    rh = np.maximum(half_h, ov_m)[:, None]  # m, r_a + r_b >= the pair's minimum
    rv = np.maximum(half_v, ov_m)[:, None]
    grow = np.stack([rh, rh, rv], axis=-1)  # (N, 1, 3)
    return lo - grow, hi + grow, w


def _box_overlap(
    lo: FloatArray, hi: FloatArray, ia: IntArray, ib: IntArray
) -> npt.NDArray[np.bool_]:
    out: npt.NDArray[np.bool_] = np.all((lo[ia] <= hi[ib]) & (lo[ib] <= hi[ia]), axis=-1)
    return out


def detect_los_allpairs(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig
) -> list[SeparationLoss]:
    """All pairs of grown window boxes, then the kernel on pairs whose boxes overlap in some
    window. Faster than the grid for small N (no hashing or sorting)."""
    points = _segments(np.asarray(points, np.float64))
    _check_time_base(points)
    ov = np.asarray(ov_m, np.float64)
    if len(points) < 2:
        return []
    lo, hi, _ = _window_boxes(points, ov, config)
    ia, ib = np.triu_indices(len(points), k=1)
    keep = np.zeros(len(ia), bool)
    for i in range(0, len(ia), _CHUNK // max(lo.shape[1], 1) + 1):
        sl = slice(i, i + _CHUNK // max(lo.shape[1], 1) + 1)
        keep[sl] = _box_overlap(lo, hi, ia[sl], ib[sl]).any(axis=1)
    return _confirm(points, ov, ia[keep].astype(np.int64), ib[keep].astype(np.int64), config)


def _screen_windows(
    points: FloatArray,
    ov_m: FloatArray,
    ia: IntArray,
    ib: IntArray,
    win: IntArray,
    *,
    w: int,
    config: MonitoringConfig,
) -> tuple[IntArray, IntArray]:
    """Loss flag on the W segments of each candidate window; returns the unique row pairs
    with a loss somewhere (their full-horizon figures come from ``_confirm``)."""
    n_seg = points.shape[1] - 1
    mh, mv = _minima(ov_m[ia], ov_m[ib], config)
    hits = np.zeros(len(ia), bool)
    step = max(1, _CHUNK // w)
    offs = np.arange(w)
    for i in range(0, len(ia), step):
        sl = slice(i, i + step)
        j = win[sl, None] * w + offs  # segment index, (C, W)
        valid = j < n_seg
        j = np.minimum(j, n_seg - 1)
        a = ia[sl, None]
        b = ib[sl, None]
        flag = segment_loss(
            points[a, j],
            points[a, j + 1],
            points[b, j],
            points[b, j + 1],
            min_h_m=mh[sl, None],
            min_v_m=mv[sl, None],
            spherical=config.spherical,
        )
        hits[sl] = (flag & valid).any(axis=1)
    n = len(points)
    code = _unique(ia[hits] * n + ib[hits])
    return code // n, code % n


def grid_candidates(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig
) -> tuple[IntArray, IntArray, IntArray, int]:
    """Candidate (row a < row b, window) triples whose grown window boxes overlap, found by
    sharing a 4D cell; also returns the window length W in steps."""
    n = len(points)
    lo, hi, w = _window_boxes(points, ov_m, config)
    nw = lo.shape[1]
    lo_f = lo.reshape(-1, 3)
    hi_f = hi.reshape(-1, 3)
    ext = hi_f - lo_f  # m, box extents
    # A cell at least as big as the median box keeps most boxes within 2 cells per axis.
    cell = np.maximum(
        np.array([config.grid_dx_m, config.grid_dy_m, config.grid_dz_m]), np.median(ext, axis=0)
    )
    i0 = np.floor(lo_f / cell).astype(np.int64)
    i1 = np.floor(hi_f / cell).astype(np.int64)
    span = i1 - i0 + 1  # cells per axis
    count = span.prod(axis=1)
    box = np.repeat(np.arange(n * nw, dtype=np.int64), count)
    start = np.repeat(np.cumsum(count) - count, count)
    k = np.arange(len(box), dtype=np.int64) - start  # index within the box's cells
    sx = span[box, 0]
    sy = span[box, 1]
    cx = i0[box, 0] + k % sx
    cy = i0[box, 1] + (k // sx) % sy
    cz = i0[box, 2] + k // (sx * sy)
    cx -= cx.min()
    cy -= cy.min()
    cz -= cz.min()
    wx = int(cx.max()) + 1
    wy = int(cy.max()) + 1
    wz = int(cz.max()) + 1
    key = (((box % nw) * wz + cz) * wy + cy) * wx + cx  # window is the 4th (time) axis
    order = np.argsort(key)
    key = key[order]
    bs = box[order]
    pa: list[IntArray] = []
    pb: list[IntArray] = []
    d = 1
    while d < len(key):
        same = key[d:] == key[:-d]  # entries d apart in one cell
        if not same.any():
            break
        pa.append(bs[:-d][same])
        pb.append(bs[d:][same])
        d += 1
    empty = np.empty(0, np.int64)
    if not pa:
        return empty, empty, empty, w
    a = np.concatenate(pa)
    b = np.concatenate(pb)
    # Same cell => same window; order by row and drop boxes met in several cells.
    code = _unique(np.minimum(a, b) * (n * nw) + np.maximum(a, b))
    ba = code // (n * nw)
    bb = code % (n * nw)
    keep = np.all((lo_f[ba] <= hi_f[bb]) & (lo_f[bb] <= hi_f[ba]), axis=1)
    ba = ba[keep]
    bb = bb[keep]
    return ba // nw, bb // nw, ba % nw, w


def detect_los_grid(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig
) -> list[SeparationLoss]:
    """The 4D grid detector (see module doc): candidates sharing a cell, a loss screen on the
    candidate windows, then the full-horizon kernel on the pairs that lose separation."""
    points = _segments(np.asarray(points, np.float64))
    _check_time_base(points)
    ov = np.asarray(ov_m, np.float64)
    if len(points) < 2:
        return []
    ia, ib, win, w = grid_candidates(points, ov, config)
    pa, pb = _screen_windows(points, ov, ia, ib, win, w=w, config=config)
    return _confirm(points, ov, pa, pb, config)


def detect_los(
    points: FloatArray, ov_m: FloatArray, config: MonitoringConfig
) -> list[SeparationLoss]:
    """All-pairs below ``config.allpairs_below`` rows, the 4D grid above."""
    if len(points) < config.allpairs_below:
        return detect_los_allpairs(points, ov_m, config)
    return detect_los_grid(points, ov_m, config)


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
    ga, gb = np.meshgrid(np.arange(len(pa)), np.arange(len(pb)), indexing="ij")
    ia = ga.ravel()
    ib = gb.ravel()
    mh = np.full(len(ia), float(min_h_m))
    mv = np.full(len(ia), float(min_v_m))
    loss, stats = _evaluate(pa[ia], pb[ib], mh, mv, spherical)
    return [(int(ia[i]), int(ib[i]), stats[i]) for i in np.nonzero(loss)[0]]
