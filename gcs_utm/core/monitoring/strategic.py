"""Strategic check of filed 4D plans: plan against plan, plan against geofence.

Plans are piecewise linear in time between their waypoints (WGS84/AMSL, POSIX t_s), converted
to the local frame. Two plans are compared over the time both are airborne, on the merged set
of both plans' waypoint times plus a ``step_s`` grid: between two consecutive merged times
both UAS move linearly, so the exact segment kernel gives the exact first loss and closest
approach (the grid only adds samples; it never decides a result).

Separation: per pair, ``MonitoringConfig.effective_minima`` (never below the sum of the two
operational-volume radii). A plan is checked against a geofence after growing the fence by the
plan's operational-volume radius (``fences.localise``): a plan closer than that radius to an
active fence counts as crossing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import LocalFence, localise
from gcs_utm.core.monitoring.geometry import FloatArray, segment_separation
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Geofence, GeofenceId, Operation, OperationId


@dataclass(frozen=True, slots=True, kw_only=True)
class PlanConflict:
    """Loss of separation between two filed plans. ``min_distance_m`` is the 3D closest
    approach at ``closest_t_s``; ``min_horizontal_m``/``min_vertical_m`` are the smallest
    horizontal and vertical distances over the common time span (each at its own instant)."""

    a: OperationId
    b: OperationId
    first_loss_t_s: float
    closest_t_s: float
    min_distance_m: float
    min_horizontal_m: float
    min_vertical_m: float


@dataclass(frozen=True, slots=True, kw_only=True)
class PlanGeofenceCrossing:
    operation_id: OperationId
    geofence_id: GeofenceId
    entry_t_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class StrategicReport:
    conflicts: tuple[PlanConflict, ...]
    crossings: tuple[PlanGeofenceCrossing, ...]


def plan_local(plan: FlightPlan, frame: LocalFrame) -> FloatArray:
    """(K, 4) east_m, north_m, alt_amsl_m, t_s of the plan's waypoints."""
    lat = np.array([w.lat_deg for w in plan.waypoints])
    lon = np.array([w.lon_deg for w in plan.waypoints])
    e, n = frame.to_local(lat, lon)
    z = np.array([w.alt_amsl_m for w in plan.waypoints])
    t = np.array([w.t_s for w in plan.waypoints])
    return np.column_stack([e, n, z, t])


def _at(pts: FloatArray, t: FloatArray) -> FloatArray:
    """Positions (len(t), 3) of a piecewise-linear 4D polyline at times t (clamped)."""
    tt = pts[:, 3]
    if len(tt) == 1:
        return np.repeat(pts[:, :3], len(t), axis=0)
    return np.column_stack([np.interp(t, tt, pts[:, k]) for k in range(3)])


def _pair_conflict(
    pa: FloatArray,
    pb: FloatArray,
    *,
    ida: OperationId,
    idb: OperationId,
    min_h: float,
    min_v: float,
    spherical: bool,
    step_s: float,
) -> PlanConflict | None:
    t0 = max(pa[0, 3], pb[0, 3])
    t1 = min(pa[-1, 3], pb[-1, 3])
    if t0 > t1:
        return None
    # Cheap reject: the two plans' boxes over the common span are farther apart than the minima.
    lo_a, hi_a = pa[:, :3].min(axis=0), pa[:, :3].max(axis=0)
    lo_b, hi_b = pb[:, :3].min(axis=0), pb[:, :3].max(axis=0)
    gap = np.maximum(np.maximum(lo_a - hi_b, lo_b - hi_a), 0.0)  # m per axis
    if spherical:
        if float(np.sqrt((gap**2).sum())) >= min_h:
            return None
    elif float(np.hypot(gap[0], gap[1])) >= min_h or gap[2] >= min_v:
        return None
    grid = np.arange(t0, t1, step_s) if step_s > 0 and t1 > t0 else np.empty(0)
    knots = np.concatenate([pa[:, 3], pb[:, 3], grid, [t0, t1]])
    t = np.unique(knots[(knots >= t0) & (knots <= t1)])
    if len(t) == 1:
        t = np.array([t[0], t[0]])
    a = _at(pa, t)
    b = _at(pb, t)
    seg = segment_separation(
        a[:-1], a[1:], b[:-1], b[1:], min_h_m=min_h, min_v_m=min_v, spherical=spherical
    )
    if not seg.loss.any():
        return None
    dt = np.diff(t)
    first_s = np.where(seg.loss, seg.first_loss_s, 0.0)  # avoids inf * 0 on still segments
    k = int(np.argmin(np.where(seg.loss, t[:-1] + first_s * dt, np.inf)))
    first = float(t[k] + seg.first_loss_s[k] * dt[k])
    c = int(np.argmin(seg.cpa_m))
    return PlanConflict(
        a=ida,
        b=idb,
        first_loss_t_s=first,
        closest_t_s=float(t[c] + seg.cpa_s[c] * dt[c]),
        min_distance_m=float(seg.cpa_m[c]),
        min_horizontal_m=float(seg.min_h_m.min()),
        min_vertical_m=float(seg.min_v_m.min()),
    )


def _fence_crossing(pts: FloatArray, fence: LocalFence) -> float | None:
    if not fence.active_between(float(pts[0, 3]), float(pts[-1, 3])):
        return None
    if len(pts) == 1:
        pts = np.vstack([pts, pts])
    lo = pts[:, :2].min(axis=0)
    hi = pts[:, :2].max(axis=0)
    bx = fence.bbox
    if lo[0] > bx[2] or lo[1] > bx[3] or hi[0] < bx[0] or hi[1] < bx[1]:
        return None
    s = fence.first_entry(pts[:-1], pts[1:])
    finite = np.isfinite(s)
    if not finite.any():
        return None
    k = int(np.argmax(finite))  # segments are in time order: the first finite is the entry
    return float(pts[k, 3] + s[k] * (pts[k + 1, 3] - pts[k, 3]))


def plan_vs_plans(
    plan: FlightPlan,
    op: Operation,
    others: Sequence[Operation],
    frame: LocalFrame,
    config: MonitoringConfig,
    *,
    step_s: float = 1.0,
) -> list[PlanConflict]:
    """Conflicts of ``plan`` (flown by ``op``, using op's operational volume) with the current
    plans of ``others`` (``op`` itself is skipped). ``PlanConflict.a`` is ``op.id``."""
    pa = plan_local(plan, frame)
    out: list[PlanConflict] = []
    for other in others:
        if other.id == op.id:
            continue
        mh, mv = config.effective_minima(op.operational_volume_m, other.operational_volume_m)
        c = _pair_conflict(
            pa,
            plan_local(other.plan, frame),
            ida=op.id,
            idb=other.id,
            min_h=mh,
            min_v=mv,
            spherical=config.spherical,
            step_s=step_s,
        )
        if c is not None:
            out.append(c)
    return out


def plan_vs_geofences(
    plan: FlightPlan,
    op: Operation,
    geofences: Sequence[Geofence],
    frame: LocalFrame,
    config: MonitoringConfig,
) -> list[PlanGeofenceCrossing]:
    """Active geofences (space and time) that ``plan`` crosses or passes closer to than
    ``op.operational_volume_m``, with the first such time."""
    del config  # the inflation is the operation's own volume; kept for a uniform signature
    pts = plan_local(plan, frame)
    out: list[PlanGeofenceCrossing] = []
    for g in geofences:
        if not g.applies_to(op.id):
            continue
        t = _fence_crossing(pts, localise(g, frame, op.operational_volume_m))
        if t is not None:
            out.append(PlanGeofenceCrossing(operation_id=op.id, geofence_id=g.id, entry_t_s=t))
    return out


def strategic_check(
    operations: Sequence[Operation],
    geofences: Sequence[Geofence],
    frame: LocalFrame,
    config: MonitoringConfig,
    *,
    step_s: float = 1.0,
) -> StrategicReport:
    """Every pair of filed plans against each other, and every plan against every geofence.
    Pairs are reported once, ``a`` before ``b`` in the order of ``operations``."""
    local = [plan_local(op.plan, frame) for op in operations]
    conflicts: list[PlanConflict] = []
    for i, a in enumerate(operations):
        for j in range(i + 1, len(operations)):
            b = operations[j]
            mh, mv = config.effective_minima(a.operational_volume_m, b.operational_volume_m)
            c = _pair_conflict(
                local[i],
                local[j],
                ida=a.id,
                idb=b.id,
                min_h=mh,
                min_v=mv,
                spherical=config.spherical,
                step_s=step_s,
            )
            if c is not None:
                conflicts.append(c)
    crossings: list[PlanGeofenceCrossing] = []
    for i, op in enumerate(operations):
        for g in geofences:
            t = _fence_crossing(local[i], localise(g, frame, op.operational_volume_m))
            if t is not None:
                crossings.append(
                    PlanGeofenceCrossing(operation_id=op.id, geofence_id=g.id, entry_t_s=t)
                )
    return StrategicReport(conflicts=tuple(conflicts), crossings=tuple(crossings))
