"""Per-cycle checks on a prediction: 4D geofences and plan conformance (vectorised).

Geofences: every predicted point AND every segment between predicted points is tested
against every active fence in space (altitude band, cylinder distance or winding polygon) and
time (activation window). A trajectory-vs-fence bounding-box prefilter keeps this near linear
in N. Conformance: 3D distance from the UAS position to the part of its plan flown within
``conformance_time_tolerance_s`` of now (the plan's own time), against the flight geometry
and operational volume radii. Units: metres, POSIX seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs_utm.core.monitoring.fences import LocalFence
from gcs_utm.core.monitoring.geometry import FloatArray, point_segment_distance
from gcs_utm.model import GeofenceId


@dataclass(frozen=True, slots=True, kw_only=True)
class FenceHit:
    row: int
    geofence_id: GeofenceId
    inside_now: bool
    entry_t_s: float


def check_geofences(points: FloatArray, fences: Sequence[LocalFence]) -> list[FenceHit]:
    """Rows of ``points`` (N, S, 4) inside a fence at their first sample (intrusion) or
    predicted to enter it later (conflict, with the entry time)."""
    if len(points) == 0 or not fences:
        return []
    if points.shape[1] == 1:
        points = np.concatenate([points, points], axis=1)
    t0 = float(points[0, 0, 3])
    t1 = float(points[0, -1, 3])
    lo = points[:, :, :2].min(axis=1)  # m, (N, 2)
    hi = points[:, :, :2].max(axis=1)
    zlo = points[:, :, 2].min(axis=1)
    zhi = points[:, :, 2].max(axis=1)
    out: list[FenceHit] = []
    for f in fences:
        if not f.active_between(t0, t1):
            continue
        cand = np.nonzero(
            (lo[:, 0] <= f.bbox[2])
            & (hi[:, 0] >= f.bbox[0])
            & (lo[:, 1] <= f.bbox[3])
            & (hi[:, 1] >= f.bbox[1])
            & (zlo <= f.z_hi)
            & (zhi >= f.z_lo)
        )[0]
        if len(cand) == 0:
            continue
        p = points[cand]
        s_n = p.shape[1] - 1
        s = f.first_entry(p[:, :-1].reshape(-1, 4), p[:, 1:].reshape(-1, 4)).reshape(-1, s_n)
        hit = np.isfinite(s)
        for i in np.nonzero(hit.any(axis=1))[0]:
            k = int(np.argmax(hit[i]))  # first segment (in time) that enters
            seg_t0 = p[i, k, 3]
            t = float(seg_t0 + s[i, k] * (p[i, k + 1, 3] - seg_t0))
            out.append(
                FenceHit(
                    row=int(cand[i]),
                    geofence_id=f.id,
                    inside_now=bool(k == 0 and s[i, 0] == 0.0),
                    entry_t_s=t,
                )
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
    table: PlanTable, pos: FloatArray, t_s: FloatArray, tolerance_s: float
) -> FloatArray:
    """3D distance (M,) from positions (M, 3) to each plan's portion within
    [t - tolerance, t + tolerance] (clamped to the plan's time span)."""
    p = table.points
    ta = p[:, :-1, 3]  # s, segment start times (M, K-1)
    tb = p[:, 1:, 3]
    lo_t = (t_s - tolerance_s)[:, None]
    hi_t = (t_s + tolerance_s)[:, None]
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
