"""Per-cycle checks on a prediction: 4D geofences and plan conformance (vectorised).

Geofences: every predicted point AND every segment between predicted points is tested
against every active fence in space (altitude band, cylinder distance or winding polygon) and
time (activation window). A trajectory-vs-fence bounding-box prefilter keeps this near linear
in N. Conformance: 3D distance from the UAS position to the part of its plan flown within
``conformance_time_tolerance_s`` of now (the plan's own time), against the flight geometry
and operational volume radii. Units: metres, POSIX seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.fences import LocalFence
from gcs_utm.core.monitoring.geometry import (
    FloatArray,
    Windows,
    point_segment_distance,
    segment_entry,
    window_extents,
)
from gcs_utm.model import GeofenceId

IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True, slots=True, kw_only=True)
class FenceHit:
    row: int
    geofence_id: GeofenceId
    inside_now: bool
    entry_t_s: float


# Segments per prefilter window when the caller supplies no windows.
_WINDOW = 10
# Prefilter grid: cell side at least this (m), and at most this many cells.
_MIN_CELL_M = 500.0
_MAX_CELLS = 1 << 18
_PAD_M = 1e-3
_PAD_S = 1e-6


def check_geofences(
    points: FloatArray, fences: Sequence[LocalFence], windows: Windows | None = None
) -> list[FenceHit]:
    """Rows of ``points`` (N, S, 4) inside a fence at their first sample (intrusion) or
    predicted to enter it later (conflict, with the entry time).

    Exact (same hits as :func:`check_geofences_bruteforce`): a conservative prefilter keeps
    every (row, segment, fence) whose bounds could meet, then the exact segment test decides.
    Prefilter: the 4D bounds of each row's time windows (``windows``, computed if not given)
    are looked up in a 2D grid in which each fence is registered over its bounding box grown
    by the largest window extent, so a window's lower corner cell lists every fence its box
    can touch; then window box vs fence box (space, band, activation), then segment box vs
    fence box, then :func:`segment_entry`, batched over all fences."""
    if len(points) == 0 or not fences:
        return []
    if points.shape[1] == 1:
        points = np.concatenate([points, points], axis=1)
    n_seg = points.shape[1] - 1
    if windows is None:
        windows = window_extents(points, _WINDOW)
    nw, w = windows.lo.shape[1], windows.w
    tab = _FenceTable(fences)
    # (window box, fence) pairs from the registration grid.
    lo = windows.lo.reshape(-1, 4)
    hi = windows.hi.reshape(-1, 4)
    box, fid = tab.candidates(lo, hi)
    keep = (
        (lo[box, 0] <= tab.bounds[fid, 2])
        & (hi[box, 0] >= tab.bounds[fid, 0])
        & (lo[box, 1] <= tab.bounds[fid, 3])
        & (hi[box, 1] >= tab.bounds[fid, 1])
        & (lo[box, 2] <= tab.pre[fid, 1])
        & (hi[box, 2] >= tab.pre[fid, 0])
        & (lo[box, 3] <= tab.pre[fid, 3])
        & (hi[box, 3] >= tab.pre[fid, 2])
    )
    box = box[keep]
    fid = fid[keep]
    if len(box) == 0:
        return []
    # Segments of the surviving windows, then a segment box test.
    row = np.repeat(box // nw, w)
    seg = (np.repeat(box % nw, w) * w + np.tile(np.arange(w), len(box))).astype(np.intp)
    fid = np.repeat(fid, w)
    valid = seg < n_seg
    row, seg, fid = row[valid], seg[valid], fid[valid]
    p0 = points[row, seg]
    p1 = points[row, seg + 1]
    smin = np.minimum(p0, p1)
    smax = np.maximum(p0, p1)
    keep = (
        (smin[:, 0] <= tab.bounds[fid, 2])
        & (smax[:, 0] >= tab.bounds[fid, 0])
        & (smin[:, 1] <= tab.bounds[fid, 3])
        & (smax[:, 1] >= tab.bounds[fid, 1])
        & (smin[:, 2] <= tab.pre[fid, 1])
        & (smax[:, 2] >= tab.pre[fid, 0])
        & (smin[:, 3] <= tab.pre[fid, 3])
        & (smax[:, 3] >= tab.pre[fid, 2])
    )
    # Each (row, fence)'s segments in time order.
    order = np.lexsort((seg[keep], fid[keep], row[keep]))
    sel = np.flatnonzero(keep)[order]
    row, seg, fid, p0, p1 = row[sel], seg[sel], fid[sel], p0[sel], p1[sel]
    s = _entries_in_order(tab, row, fid, p0, p1)
    hit = np.isfinite(s)
    row, seg, fid, s, p0, p1 = row[hit], seg[hit], fid[hit], s[hit], p0[hit], p1[hit]
    # The first segment (in time) entering each (row, fence).
    t_in = p0[:, 3] + s * (p1[:, 3] - p0[:, 3])
    first = np.ones(len(row), bool)
    first[1:] = (row[1:] != row[:-1]) | (fid[1:] != fid[:-1])
    return [
        FenceHit(
            row=int(row[i]),
            geofence_id=fences[int(fid[i])].id,
            inside_now=bool(seg[i] == 0 and s[i] == 0.0),
            entry_t_s=float(t_in[i]),
        )
        for i in np.nonzero(first)[0]
    ]


def _entries_in_order(
    tab: _FenceTable, row: IntArray, fid: IntArray, p0: FloatArray, p1: FloatArray
) -> FloatArray:
    """The exact entry parameter of each segment (p0, p1) against fence ``fid``, +inf where
    it does not enter, or where an earlier segment of the same (row, fence) enters (only the
    first entry is reported). Segments come grouped by (row, fence), each group in time
    order; they are tested in rounds of 1, 2, 4, ... segments per group, and a group leaves
    once a segment enters: a UAS inside a fence's box for its whole horizon costs a few
    tests, not one per segment. Each segment's figure is the one a single test gives."""
    out = np.full(len(row), np.inf)
    if len(row) == 0:
        return out
    new = np.ones(len(row), bool)
    new[1:] = (row[1:] != row[:-1]) | (fid[1:] != fid[:-1])
    starts = np.flatnonzero(new)
    group = np.cumsum(new) - 1
    rank = np.arange(len(row)) - starts[group]  # position of the segment within its group
    done = np.zeros(len(starts), bool)
    lo, width, top = 0, 1, int(rank.max())
    while lo <= top:
        sel = np.flatnonzero((rank >= lo) & (rank < lo + width) & ~done[group])
        if len(sel):
            out[sel] = tab.entry(p0[sel], p1[sel], fid[sel])
            done[group[sel[np.isfinite(out[sel])]]] = True
        lo, width = lo + width, width * 2
    return out


def check_geofences_bruteforce(points: FloatArray, fences: Sequence[LocalFence]) -> list[FenceHit]:
    """Every segment of every row against every fence with the exact test (no prefilter):
    the oracle :func:`check_geofences` must match, hit for hit."""
    if len(points) == 0 or not fences:
        return []
    if points.shape[1] == 1:
        points = np.concatenate([points, points], axis=1)
    s_n = points.shape[1] - 1
    out: list[FenceHit] = []
    for f in fences:
        s = f.first_entry(points[:, :-1].reshape(-1, 4), points[:, 1:].reshape(-1, 4))
        s = s.reshape(-1, s_n)
        hit = np.isfinite(s)
        for i in np.nonzero(hit.any(axis=1))[0]:
            k = int(np.argmax(hit[i]))
            t0 = points[i, k, 3]
            out.append(
                FenceHit(
                    row=int(i),
                    geofence_id=f.id,
                    inside_now=bool(k == 0 and s[i, 0] == 0.0),
                    entry_t_s=float(t0 + s[i, k] * (points[i, k + 1, 3] - t0)),
                )
            )
    return out


def _edge_class(n_edges: int) -> int:
    """Padded edge count: the next of 4, 6, 8, 12, 16, 24, ... (at most 1/3 padding)."""
    e = 4
    while e < n_edges:
        e = e * 3 // 2 if e & (e - 1) == 0 else e * 4 // 3
    return e


class _FenceTable:
    """The active fences as arrays for the batched prefilter and exact test."""

    def __init__(self, fences: Sequence[LocalFence]) -> None:
        self.fences = fences
        # Prefilter bounds grown by a hair beyond the exact test's own tolerances (a tangent
        # touch counts as inside there), so rounding can never drop a hit.
        # The exact test uses the fences' own values (z_lo .. t_hi).
        grow = np.array([-_PAD_M, -_PAD_M, _PAD_M, _PAD_M])
        self.bounds = np.array([f.bbox for f in fences], np.float64).reshape(-1, 4) + grow
        self.z_lo = np.array([f.z_lo for f in fences], np.float64)
        self.z_hi = np.array([f.z_hi for f in fences], np.float64)
        self.t_lo = np.array([f.t_lo for f in fences], np.float64)
        self.t_hi = np.array([f.t_hi for f in fences], np.float64)
        # Prefilter: band and window grown by the same hair.
        self.pre = np.column_stack(
            [self.z_lo - _PAD_M, self.z_hi + _PAD_M, self.t_lo - _PAD_S, self.t_hi + _PAD_S]
        )
        self.is_cyl = np.array([f.center is not None for f in fences], bool)
        self.cx = np.array([f.center[0] if f.center else 0.0 for f in fences], np.float64)
        self.cy = np.array([f.center[1] if f.center else 0.0 for f in fences], np.float64)
        self.r = np.array([f.radius_m for f in fences], np.float64)
        # Polygons by size class (edge count rounded up to a power of two), each class one
        # (F, E, 4) table padded with zero-length edges at the first vertex.
        self.cls = np.zeros(len(fences), np.intp)
        self.slot = np.zeros(len(fences), np.intp)
        self.edge_tables: dict[int, FloatArray] = {}
        groups: dict[int, list[int]] = {}
        for i, f in enumerate(fences):
            if f.edges is not None and f.center is None:
                e = _edge_class(len(f.edges))
                groups.setdefault(e, []).append(i)
        for e, members in groups.items():
            table = np.empty((len(members), e, 4))
            for k, i in enumerate(members):
                edges = fences[i].edges
                assert edges is not None
                table[k, : len(edges)] = edges
                table[k, len(edges) :] = edges[0, [0, 1, 0, 1]]
                self.cls[i] = e
                self.slot[i] = k
            self.edge_tables[e] = table

    def candidates(self, lo: FloatArray, hi: FloatArray) -> tuple[IntArray, IntArray]:
        """(box, fence) index pairs whose horizontal boxes may overlap (a superset)."""
        ext_x = float((hi[:, 0] - lo[:, 0]).max())  # m, largest box extent per axis
        ext_y = float((hi[:, 1] - lo[:, 1]).max())
        b = self.bounds
        reg = np.column_stack([b[:, 0] - ext_x, b[:, 1] - ext_y, b[:, 2], b[:, 3]])
        gx0, gy0 = float(reg[:, 0].min()), float(reg[:, 1].min())
        gx1, gy1 = float(reg[:, 2].max()), float(reg[:, 3].max())
        cell = max(_MIN_CELL_M, math.sqrt((gx1 - gx0) * (gy1 - gy0) / _MAX_CELLS))
        nx = int((gx1 - gx0) // cell) + 1
        ny = int((gy1 - gy0) // cell) + 1
        c0 = np.floor((reg[:, :2] - (gx0, gy0)) / cell).astype(np.intp)
        c1 = np.floor((reg[:, 2:] - (gx0, gy0)) / cell).astype(np.intp)
        span = c1 - c0 + 1  # cells per axis of each fence's registration
        count = span[:, 0] * span[:, 1]
        owner = np.repeat(np.arange(len(b)), count)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
        cell_of = (c0[owner, 1] + k // span[owner, 0]) * nx + c0[owner, 0] + k % span[owner, 0]
        order = np.argsort(cell_of, kind="stable")
        listed = owner[order]
        start = np.zeros(nx * ny + 1, np.intp)
        np.cumsum(np.bincount(cell_of, minlength=nx * ny), out=start[1:])
        # Each box by the cell of its lower corner.
        bx = np.floor((lo[:, 0] - gx0) / cell)
        by = np.floor((lo[:, 1] - gy0) / cell)
        inside = (bx >= 0) & (bx < nx) & (by >= 0) & (by < ny)
        boxes = np.nonzero(inside)[0]
        flat_box = by[boxes].astype(np.intp) * nx + bx[boxes].astype(np.intp)
        first = start[flat_box]
        count = start[flat_box + 1] - first
        box = np.repeat(boxes, count)
        offset = np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)
        return box, listed[np.repeat(first, count) + offset]

    def entry(self, p0: FloatArray, p1: FloatArray, fid: IntArray) -> FloatArray:
        """Exact first entry parameter per segment against its fence ``fid``."""
        out = np.full(len(p0), np.inf)
        cyl = self.is_cyl[fid]
        if cyl.any():
            f = fid[cyl]
            out[cyl] = segment_entry(
                p0[cyl],
                p1[cyl],
                edges=None,
                center=(self.cx[f], self.cy[f]),
                radius_m=self.r[f],
                z_lo=self.z_lo[f],
                z_hi=self.z_hi[f],
                t_lo=self.t_lo[f],
                t_hi=self.t_hi[f],
            )
        for e, table in self.edge_tables.items():
            sel = np.nonzero(~cyl & (self.cls[fid] == e))[0]
            if len(sel) == 0:
                continue
            f = fid[sel]
            out[sel] = segment_entry(
                p0[sel],
                p1[sel],
                edges=table[self.slot[f]],
                center=None,
                radius_m=0.0,
                z_lo=self.z_lo[f],
                z_hi=self.z_hi[f],
                t_lo=self.t_lo[f],
                t_hi=self.t_hi[f],
            )
        return out


@dataclass(frozen=True, slots=True, eq=False)
class PlanTable:
    """Plans packed for vectorised conformance: (M, K, 4) local points padded by repeating
    the last waypoint (zero-length tail segments change no distance)."""

    points: FloatArray


def pack_plans(plans: Sequence[FloatArray]) -> PlanTable:
    k = max((len(p) for p in plans), default=1)
    out = np.empty((len(plans), max(k, 2), 4))
    for i, p in enumerate(plans):
        out[i, : len(p)] = p
        out[i, len(p) :] = p[-1]
    return PlanTable(out)


def plan_distance(
    table: PlanTable,
    pos: FloatArray,
    t_s: FloatArray,
    tolerance_s: float,
    window: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """3D distance (M,) from positions (M, 3) to each plan's portion within
    [t - tolerance, t + tolerance] (clamped to the plan's time span), or within the plan
    times ``window`` (earliest, latest; per row) when given (along_track.py)."""
    p = table.points
    ta = p[:, :-1, 3]  # s, segment start times (M, K-1)
    tb = p[:, 1:, 3]
    if window is None:
        window = (t_s - tolerance_s, t_s + tolerance_s)
    lo_t = window[0][:, None]
    hi_t = window[1][:, None]
    dur = tb - ta
    safe = np.where(dur > 0, dur, 1.0)
    u0 = np.clip((lo_t - ta) / safe, 0.0, 1.0)  # clip each segment to the time window
    u1 = np.clip((hi_t - ta) / safe, 0.0, 1.0)
    overlap = (tb >= lo_t) & (ta <= hi_t)
    a = p[:, :-1, :3] + u0[..., None] * (p[:, 1:, :3] - p[:, :-1, :3])  # m
    b = p[:, :-1, :3] + u1[..., None] * (p[:, 1:, :3] - p[:, :-1, :3])  # m
    d = np.where(overlap, point_segment_distance(pos[:, None, :], a, b), np.inf)
    # Outside the plan's span the window may miss every segment: the plan's position is then
    # its first (before take-off time) or last (after the last waypoint) point.
    ref = np.where((t_s < p[:, 0, 3])[:, None], p[:, 0, :3], p[:, -1, :3])  # m
    inside_span = (t_s >= p[:, 0, 3]) & (t_s <= p[:, -1, 3])
    d_ref = np.where(inside_span, np.inf, np.sqrt(((pos - ref) ** 2).sum(axis=1)))
    out: FloatArray = np.minimum(d.min(axis=1), d_ref)
    return out
