"""The reference the strategic check is tested against: every pair of plans through the exact
kernel, every plan against every geofence (what ``strategic_check`` and ``plan_vs_plans`` did
before the space-time index). Quadratic: for tests only."""

from __future__ import annotations

from collections.abc import Sequence

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.strategic import (
    PlanConflict,
    PlanGeofenceCrossing,
    StrategicReport,
    _fence_crossing,
    _pair_conflict,
    plan_local,
)
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Geofence, Operation


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
