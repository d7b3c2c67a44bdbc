"""Exact geometric kernels shared by tactical Monitoring and the strategic check.

All arrays are float64 in the airspace's local frame: east_m, north_m, alt_amsl_m, t_s.
Kernels are vectorised over leading axes; a "segment" is the straight 4D motion between two
consecutive samples, parameterised by s in [0, 1] (position and time both linear in s).

Invariants:
- a loss of separation (cylinder mode) needs the horizontal distance < min_h AND the vertical
  distance < min_v at the SAME instant; strict inequalities, so a tangent touch is not a loss;
- polygons are tested with the signed-angle (winding) sum, which is correct for concave
  polygons; points on the boundary count as inside (conservative for geofences).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

# Relative motion below this (m^2 per segment) is treated as none: avoids dividing by ~0.
_EPS_A = 1e-12
_EPS_V = 1e-9


def ring_edges(vx: FloatArray, vy: FloatArray) -> FloatArray:
    """Closed ring (vertices (E,), first not repeated) -> (E, 4) edges x0, y0, x1, y1."""
    vx = np.asarray(vx, np.float64)
    vy = np.asarray(vy, np.float64)
    return np.stack([vx, vy, np.roll(vx, -1), np.roll(vy, -1)], axis=1)


def point_in_polygon(x: FloatArray, y: FloatArray, vx: FloatArray, vy: FloatArray) -> BoolArray:
    """Points (x, y) (any shape) inside the polygon with vertices (vx, vy) (E,), winding rule.

    Signed-angle method (paper §4.4): the sum of the signed angles subtended by the edges is
    +-2 pi inside and 0 outside, for any simple polygon (convex or not). Points within 1e-9 m
    of an edge count as inside.
    """
    return points_in_edges(x, y, ring_edges(vx, vy))


def points_in_edges(x: FloatArray, y: FloatArray, edges: FloatArray) -> BoolArray:
    """Winding test against any set of closed rings given as (E, 4) edges. Holes must be
    oriented opposite to their exterior (as ``shapely.geometry.polygon.orient`` does), so
    their signed angles cancel the exterior's.

    ``edges`` may also be (M, E, 4), one edge set per point of ``x``, ``y`` (M,); sets are
    padded with zero-length edges at a vertex, which add no angle and cross nothing."""
    x = np.asarray(x, np.float64)[..., None]
    y = np.asarray(y, np.float64)[..., None]
    ax = edges[..., 0] - x  # m, (..., E)
    ay = edges[..., 1] - y  # m
    bx = edges[..., 2] - x  # m, next vertex
    by = edges[..., 3] - y  # m
    cross = ax * by - ay * bx  # m^2
    dot = ax * bx + ay * by  # m^2
    total = np.arctan2(cross, dot).sum(axis=-1)  # rad
    inside: BoolArray = np.abs(total) > np.pi
    # On an edge the angle is +-pi and the sum is unreliable: treat as inside.
    ex = bx - ax
    ey = by - ay
    seg2 = ex * ex + ey * ey
    u = np.clip(-(ax * ex + ay * ey) / np.where(seg2 > 0, seg2, 1.0), 0.0, 1.0)
    dx = ax + u * ex
    dy = ay + u * ey
    on_edge = (dx * dx + dy * dy <= 1e-18).any(axis=-1)
    out: BoolArray = inside | on_edge
    return out


@dataclass(frozen=True, slots=True)
class Windows:
    """Axis-aligned bounds of each row's samples per time window: ``lo``, ``hi`` (N, nw, 4)
    (east_m, north_m, alt_amsl_m, t_s). Window j holds segments j*w .. j*w + w - 1, so its
    bounds cover samples j*w .. j*w + w (the closing sample included): every point of every
    segment of the window lies in its box (segments are straight)."""

    lo: FloatArray
    hi: FloatArray
    w: int


def window_extents(points: FloatArray, w: int) -> Windows:
    """Per-window bounds (see :class:`Windows`) of ``points`` (N, S >= 2, 4), ``w`` >= 1
    segments per window (clipped to S - 1)."""
    n_seg = points.shape[1] - 1
    w = max(1, min(int(w), n_seg))
    starts = np.arange(0, n_seg, w)
    # reduceat over [start, start + w + 1) for every window: the interleaved indices make the
    # odd slots single samples (discarded); the last window runs to the end.
    idx = np.empty(2 * len(starts) - 1, np.intp)
    idx[0::2] = starts
    idx[1::2] = starts[:-1] + w + 1
    lo = np.minimum.reduceat(points, idx, axis=1)[:, 0::2]
    hi = np.maximum.reduceat(points, idx, axis=1)[:, 0::2]
    return Windows(lo, hi, w)


def _quad_interval(
    a: FloatArray, b: FloatArray, c: FloatArray, r: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Open interval of s where a s^2 + b s + c < r^2 (a >= 0); empty as (1, 0)."""
    cc = c - r * r
    disc = b * b - 4.0 * a * cc
    moving = a > _EPS_A
    sq = np.sqrt(np.maximum(disc, 0.0))
    den = np.where(moving, 2.0 * a, 1.0)
    lo = np.where(moving, (-b - sq) / den, np.where(cc < 0.0, -np.inf, 1.0))
    hi = np.where(moving, (-b + sq) / den, np.where(cc < 0.0, np.inf, 0.0))
    empty = moving & (disc <= 0.0)
    return np.where(empty, 1.0, lo), np.where(empty, 0.0, hi)


@dataclass(frozen=True, slots=True)
class SegmentSeparation:
    """Per-segment-pair result arrays (same shape as the inputs' leading axes)."""

    loss: BoolArray
    first_loss_s: FloatArray  # segment parameter of first loss (valid where loss)
    cpa_s: FloatArray  # parameter of the 3D closest approach
    cpa_m: FloatArray  # 3D distance at cpa_s
    min_h_m: FloatArray  # minimum horizontal distance over the segment
    min_v_m: FloatArray  # minimum vertical distance over the segment


def _loss_interval(
    d0: tuple[FloatArray, FloatArray, FloatArray],
    v: tuple[FloatArray, FloatArray, FloatArray],
    rh: FloatArray,
    rv: FloatArray,
    spherical: bool,
) -> tuple[FloatArray, FloatArray]:
    """Parameter interval [lo, hi] (clipped to [0, 1]) of loss; lo >= hi means none.
    ``d0``, ``v``: the relative position at s = 0 and the relative motion per segment, one
    array per axis (east, north, up)."""
    ah = v[0] ** 2 + v[1] ** 2  # m^2
    bh = 2.0 * (d0[0] * v[0] + d0[1] * v[1])  # m^2
    ch = d0[0] ** 2 + d0[1] ** 2  # m^2
    if spherical:
        lo, hi = _quad_interval(ah + v[2] ** 2, bh + 2.0 * d0[2] * v[2], ch + d0[2] ** 2, rh)
    else:
        lo_h, hi_h = _quad_interval(ah, bh, ch, rh)
        vz = v[2]  # m per segment
        moving = np.abs(vz) > _EPS_V
        safe = np.where(moving, vz, 1.0)
        s1 = (-rv - d0[2]) / safe
        s2 = (rv - d0[2]) / safe
        inside_z = np.abs(d0[2]) < rv
        lo_v = np.where(moving, np.minimum(s1, s2), np.where(inside_z, -np.inf, 1.0))
        hi_v = np.where(moving, np.maximum(s1, s2), np.where(inside_z, np.inf, 0.0))
        lo = np.maximum(lo_h, lo_v)
        hi = np.minimum(hi_h, hi_v)
    return np.maximum(lo, 0.0), np.minimum(hi, 1.0)


def _relative(
    a0: FloatArray, a1: FloatArray, b0: FloatArray, b1: FloatArray
) -> tuple[tuple[FloatArray, FloatArray, FloatArray], tuple[FloatArray, FloatArray, FloatArray]]:
    d0 = a0[..., :3] - b0[..., :3]  # m, relative position at s=0
    v = (a1[..., :3] - b1[..., :3]) - d0  # m per segment, relative motion
    return (d0[..., 0], d0[..., 1], d0[..., 2]), (v[..., 0], v[..., 1], v[..., 2])


def segment_separation(
    a0: FloatArray,
    a1: FloatArray,
    b0: FloatArray,
    b1: FloatArray,
    *,
    min_h_m: FloatArray | float,
    min_v_m: FloatArray | float,
    spherical: bool = False,
) -> SegmentSeparation:
    """Exact closest approach and loss test between simultaneous segments a0->a1, b0->b1.

    ``a0`` etc. are (..., >=3) arrays of (east_m, north_m, alt_amsl_m[, t_s]); both objects
    move linearly over the same time span. ``spherical`` uses ``min_h_m`` as a 3D distance.
    """
    d0, v = _relative(a0, a1, b0, b1)
    return relative_separation(d0, v, min_h_m=min_h_m, min_v_m=min_v_m, spherical=spherical)


def relative_separation(
    d0: tuple[FloatArray, FloatArray, FloatArray],
    v: tuple[FloatArray, FloatArray, FloatArray],
    *,
    min_h_m: FloatArray | float,
    min_v_m: FloatArray | float,
    spherical: bool = False,
) -> SegmentSeparation:
    """:func:`segment_separation` from the relative position ``d0`` at s = 0 and the relative
    motion ``v`` per segment, one array per axis (the same floats either way)."""
    lo, hi = relative_loss_interval(d0, v, min_h_m=min_h_m, min_v_m=min_v_m, spherical=spherical)
    loss = lo < hi
    cpa_s, cpa_m, min_h, min_v = relative_approach(d0, v)
    return SegmentSeparation(loss, np.where(loss, lo, np.inf), cpa_s, cpa_m, min_h, min_v)


def relative_loss_interval(
    d0: tuple[FloatArray, FloatArray, FloatArray],
    v: tuple[FloatArray, FloatArray, FloatArray],
    *,
    min_h_m: FloatArray | float,
    min_v_m: FloatArray | float,
    spherical: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Segment parameter interval [lo, hi] (within [0, 1]) where the pair is in loss of
    separation; a loss exists iff lo < hi, and then ``lo`` is the parameter of first loss."""
    return _loss_interval(
        d0, v, np.asarray(min_h_m, np.float64), np.asarray(min_v_m, np.float64), spherical
    )


def relative_approach(
    d0: tuple[FloatArray, FloatArray, FloatArray],
    v: tuple[FloatArray, FloatArray, FloatArray],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Closest approach on each segment from the relative position ``d0`` and motion ``v``:
    (cpa_s, cpa_m, min_h_m, min_v_m) as in :class:`SegmentSeparation`."""
    ah = v[0] ** 2 + v[1] ** 2  # m^2
    bh = 2.0 * (d0[0] * v[0] + d0[1] * v[1])  # m^2
    ch = d0[0] ** 2 + d0[1] ** 2  # m^2
    az = v[2] ** 2  # m^2
    bz = 2.0 * d0[2] * v[2]  # m^2
    cz = d0[2] ** 2  # m^2
    a3 = ah + az
    cpa_s = np.where(a3 > _EPS_A, np.clip(-(bh + bz) / np.where(a3 > _EPS_A, 2 * a3, 1), 0, 1), 0)
    cpa_m = np.sqrt(np.maximum(a3 * cpa_s**2 + (bh + bz) * cpa_s + ch + cz, 0.0))
    sh = np.where(ah > _EPS_A, np.clip(-bh / np.where(ah > _EPS_A, 2 * ah, 1), 0, 1), 0)
    min_h = np.sqrt(np.maximum(ah * sh**2 + bh * sh + ch, 0.0))
    z0 = d0[2]
    z1 = z0 + v[2]
    min_v = np.where(z0 * z1 <= 0.0, 0.0, np.minimum(np.abs(z0), np.abs(z1)))
    return cpa_s, cpa_m, min_h, min_v


def segment_entry(
    p0: FloatArray,
    p1: FloatArray,
    *,
    edges: FloatArray | None,
    center: tuple[float, float] | tuple[FloatArray, FloatArray] | None,
    radius_m: float | FloatArray,
    z_lo: float | FloatArray,
    z_hi: float | FloatArray,
    t_lo: float | FloatArray,
    t_hi: float | FloatArray,
) -> FloatArray:
    """First parameter s in [0, 1] at which segment p0->p1 ((M, 4) east, north, alt, t) is
    inside a 4D prism, or +inf. The prism is a polygon (``edges``, (E, 4), see
    :func:`points_in_edges`) or a circle (center, radius_m), an altitude band [z_lo, z_hi]
    and an activation window [t_lo, t_hi] (closed; use +-inf for unbounded).

    Every prism parameter may instead be given per segment: (M,) arrays, centre as a pair of
    (M,) arrays, edges (M, E, 4) padded as :func:`points_in_edges` allows.

    Exact for polygons: the inside set along the segment starts at s_lo (the start of the
    altitude/time window) or at the first edge crossing after it.
    """
    d = p1 - p0  # (M, 4) per segment
    lo, hi = _band_window(p0, d, (z_lo, z_hi), (t_lo, t_hi))
    ok = lo <= hi
    out = np.full(len(p0), np.inf)
    if not ok.any():
        return out
    if center is not None:
        return _circle_entry(p0, d, center=center, radius_m=radius_m, lo=lo, hi=hi, ok=ok, out=out)
    assert edges is not None
    sx = p0[:, 0] + lo * d[:, 0]  # m, position at s = lo
    sy = p0[:, 1] + lo * d[:, 1]
    inside_lo = points_in_edges(sx, sy, edges) & ok
    out[inside_lo] = lo[inside_lo]
    rest = ok & ~inside_lo
    if rest.any():
        idx = np.nonzero(rest)[0]
        out[idx] = _first_edge_crossing(
            p0[idx], d[idx], edges[idx] if edges.ndim == 3 else edges, lo[idx], hi[idx]
        )
    return out


_Bound = float | FloatArray


def _band_window(
    p0: FloatArray, d: FloatArray, band: tuple[_Bound, _Bound], window: tuple[_Bound, _Bound]
) -> tuple[FloatArray, FloatArray]:
    """Parameter interval [lo, hi] of each segment within the altitude band and the
    activation window (empty: lo > hi)."""
    lo = np.zeros(len(p0))
    hi = np.ones(len(p0))
    for k, (a, b) in ((2, band), (3, window)):
        moving = np.abs(d[:, k]) > _EPS_V
        safe = np.where(moving, d[:, k], 1.0)
        with np.errstate(invalid="ignore"):
            s1 = (a - p0[:, k]) / safe
            s2 = (b - p0[:, k]) / safe
        inside = (p0[:, k] >= a) & (p0[:, k] <= b)
        lo = np.maximum(lo, np.where(moving, np.minimum(s1, s2), np.where(inside, 0.0, 2.0)))
        hi = np.minimum(hi, np.where(moving, np.maximum(s1, s2), np.where(inside, 1.0, -1.0)))
        hi = np.where(np.greater(a, b), -1.0, hi)  # an inverted band or window is empty
    return lo, hi


def _circle_entry(
    p0: FloatArray,
    d: FloatArray,
    *,
    center: tuple[float, float] | tuple[FloatArray, FloatArray],
    radius_m: _Bound,
    lo: FloatArray,
    hi: FloatArray,
    ok: BoolArray,
    out: FloatArray,
) -> FloatArray:
    """:func:`segment_entry` for a circle: the first s within [lo, hi] inside the disc."""
    rx = p0[:, 0] - center[0]
    ry = p0[:, 1] - center[1]
    a2 = d[:, 0] ** 2 + d[:, 1] ** 2
    b2 = 2.0 * (rx * d[:, 0] + ry * d[:, 1])
    c2 = rx * rx + ry * ry
    # closed disc: nudge the radius so a touch counts as inside
    r = np.broadcast_to(np.asarray(radius_m, np.float64) * (1 + 1e-12) + 1e-9, lo.shape)
    clo, chi = _quad_interval(a2, b2, c2, r)
    s_in = np.maximum(lo, clo)
    good = ok & (s_in <= np.minimum(hi, chi))
    out[good] = s_in[good]
    return out


def _first_edge_crossing(
    p0: FloatArray, d: FloatArray, e: FloatArray, lo: FloatArray, hi: FloatArray
) -> FloatArray:
    """First s in [lo, hi] at which each segment (starting outside the polygon at lo)
    crosses one of the edges ``e`` ((E, 4), or (m, E, 4) per segment); +inf if none."""
    ax = p0[:, 0, None]
    ay = p0[:, 1, None]
    dx = d[:, 0, None]
    dy = d[:, 1, None]
    fx = e[..., 2] - e[..., 0]  # m, edge vectors (E,) or (m, E)
    fy = e[..., 3] - e[..., 1]
    wx = e[..., 0] - ax  # m, (m, E)
    wy = e[..., 1] - ay
    den = dx * fy - dy * fx  # m^2
    par = np.abs(den) < 1e-12
    dsafe = np.where(par, 1.0, den)
    s = (wx * fy - wy * fx) / dsafe
    u = (wx * dy - wy * dx) / dsafe
    tol = 1e-12
    hit = (~par) & (u >= -tol) & (u <= 1 + tol) & (s >= lo[:, None] - tol)
    hit &= s <= hi[:, None] + tol
    out: FloatArray = np.where(hit, np.maximum(s, lo[:, None]), np.inf).min(axis=1)
    return out


def point_segment_distance(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """3D distance from points p (..., 3) to segments a->b (..., 3), broadcasting."""
    ab = b - a  # m
    ab2 = (ab * ab).sum(axis=-1)  # m^2
    u = np.clip(((p - a) * ab).sum(axis=-1) / np.where(ab2 > 0, ab2, 1.0), 0.0, 1.0)
    q = a + u[..., None] * ab
    dist: FloatArray = np.sqrt(((p - q) ** 2).sum(axis=-1))
    return dist
