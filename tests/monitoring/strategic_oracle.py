"""The reference the strategic check is tested against: every pair of plans through the exact
kernel, one pair at a time, every plan against every geofence (what ``strategic_check`` and
``plan_vs_plans`` did before the space-time index and the batched exact check of
``pair_check``). Quadratic: for tests only.

:func:`pair_conflict` is the definition of one pair's result, as the product computed it pair
by pair before ``pair_check`` (which must give the same figures, bit for bit): sample the
common time span at both plans' waypoint times, its ends and the ``step_s`` grid, interpolate
both plans there and run the segment kernel on every sub-segment."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.geometry import FloatArray, segment_separation
from gcs_utm.core.monitoring.strategic import (
    PlanConflict,
    PlanGeofenceCrossing,
    StrategicReport,
    _fence_crossing,
    plan_local,
)
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Geofence, Operation, OperationId


def _at(pts: FloatArray, t: FloatArray) -> FloatArray:
    """Positions (len(t), 3) of a piecewise-linear 4D polyline at times t (clamped)."""
    tt = pts[:, 3]
    if len(tt) == 1:
        return np.repeat(pts[:, :3], len(t), axis=0)
    return np.column_stack([np.interp(t, tt, pts[:, k]) for k in range(3)])


def _samples(
    pa: FloatArray, pb: FloatArray, min_h: float, min_v: float, spherical: bool, step_s: float
) -> FloatArray | None:
    """The pair's sample times (None: it cannot conflict: no common span, or boxes apart)."""
    t0 = max(pa[0, 3], pb[0, 3])
    t1 = min(pa[-1, 3], pb[-1, 3])
    if t0 > t1:
        return None
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
    t: FloatArray = np.unique(knots[(knots >= t0) & (knots <= t1)])
    return np.array([t[0], t[0]]) if len(t) == 1 else t


def pair_conflict(
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
    """The exact check of one pair, every sub-segment through the kernel."""
    t = _samples(pa, pb, min_h, min_v, spherical, step_s)
    if t is None:
        return None
    a, b = _at(pa, t), _at(pb, t)
    seg = segment_separation(
        a[:-1], a[1:], b[:-1], b[1:], min_h_m=min_h, min_v_m=min_v, spherical=spherical
    )
    if not seg.loss.any():
        return None
    dt = np.diff(t)
    first_s = np.where(seg.loss, seg.first_loss_s, 0.0)  # avoids inf * 0 on still segments
    k = int(np.argmin(np.where(seg.loss, t[:-1] + first_s * dt, np.inf)))
    c = int(np.argmin(seg.cpa_m))
    return PlanConflict(
        a=ida,
        b=idb,
        first_loss_t_s=float(t[k] + seg.first_loss_s[k] * dt[k]),
        closest_t_s=float(t[c] + seg.cpa_s[c] * dt[c]),
        min_distance_m=float(seg.cpa_m[c]),
        min_horizontal_m=float(seg.min_h_m.min()),
        min_vertical_m=float(seg.min_v_m.min()),
    )


def plan_vs_plans_allpairs(
    plan: FlightPlan,
    op: Operation,
    others: Sequence[Operation],
    frame: LocalFrame,
    config: MonitoringConfig,
    *,
    step_s: float = 1.0,
) -> list[PlanConflict]:
    pa = plan_local(plan, frame)
    out: list[PlanConflict] = []
    for other in others:
        if other.id == op.id:
            continue
        mh, mv = config.effective_minima(op.operational_volume_m, other.operational_volume_m)
        c = pair_conflict(
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


def strategic_check_allpairs(
    operations: Sequence[Operation],
    geofences: Sequence[Geofence],
    frame: LocalFrame,
    config: MonitoringConfig,
    *,
    step_s: float = 1.0,
) -> StrategicReport:
    local = [plan_local(op.plan, frame) for op in operations]
    conflicts: list[PlanConflict] = []
    for i, a in enumerate(operations):
        for j in range(i + 1, len(operations)):
            b = operations[j]
            mh, mv = config.effective_minima(a.operational_volume_m, b.operational_volume_m)
            c = pair_conflict(
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
