"""Emergency actions that create geofences (paper use cases 2 and 3): suspend a jammed or
spoofed UAS with a dynamic geofence around it, a temporary geofence around a lost UAS's
predicted position, an alert's area as a geofence; every other operation the new fence
blocks is rerouted (:func:`~.single.single`). Pure; they update EM's state through the
:class:`~.context.EmContext` they are given."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import ACTOR, REROUTE_MANEUVERS, Case, Decision, Mode
from gcs_utm.core.emergency.single import single
from gcs_utm.core.monitoring.strategic import plan_vs_geofences
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
    LatLon,
    OperationId,
    ThreatKind,
)


def _cylinder(  # noqa: PLR0917 - private helper, one call per geofence kind
    em: EmContext,
    gid: str,
    east_m: float,
    north_m: float,
    alt_amsl_m: float,
    radius_m: float,
    band_m: float,
    now: float,
    duration_s: float,
    reason: str,
    exempt: tuple[OperationId, ...] = (),
) -> Geofence:
    lat, lon = em.frame.point_to_wgs84(east_m, north_m)
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=alt_amsl_m - band_m,
        max_alt_amsl_m=alt_amsl_m + band_m,
        center=LatLon(lat_deg=lat, lon_deg=lon),
        radius_m=radius_m,
        start_t_s=now,
        end_t_s=now + duration_s,
        kind=GeofenceKind.DYNAMIC,
        reason=reason,
        source=ACTOR,
        exempt=exempt,
    )


def _reroute_affected(
    em: EmContext,
    case: Case,
    fence: Geofence,
    snapshot: AirspaceSnapshot,
    exclude: set[OperationId],
) -> Decision:
    """Reroute every other operation whose plan the new fence now blocks (use case 2)."""
    d = Decision()
    for op in snapshot.operations.values():
        if op.id in exclude or op.plan.end_t_s < snapshot.t_s:
            continue
        if not plan_vs_geofences(op.plan, op, [fence], em.frame, em.monitoring):
            continue
        sub = replace(
            case.threat,
            kind=ThreatKind.GEOFENCE_CONFLICT,
            uas_ids=(op.id,),
            geofence_id=fence.id,
            area=fence,
        )
        d = d.merge(single(em, case, op.id, snapshot, REROUTE_MANEUVERS, threat=sub))
    return d


def suspend(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision:
    now = snapshot.t_s
    cfg = em.config
    t = case.threat
    kind = CommandKind.HOLD if cfg.suspend_command == "hold" else CommandKind.LAND
    d = Decision()
    for op_id in t.uas_ids:
        op = snapshot.operations.get(op_id)
        if t.position is not None:
            e, n = em.frame.point_to_local(t.position.lat_deg, t.position.lon_deg)
            z = t.position.alt_amsl_m
        elif op is not None:
            e, n, z = (float(v) for v in em.td.current_xyz(op, snapshot))
        else:
            d = d.merge(Decision(escalations=(f"{t.id}: {t.kind.value} for unknown {op_id}",)))
            continue
        fence = _cylinder(
            em,
            f"em-{t.id}-{op_id}",
            e,
            n,
            z,
            cfg.jamming_radius_m,
            cfg.jamming_band_m,
            now,
            cfg.jamming_duration_s,
            f"{t.kind.value} around {op_id}",
            exempt=(op_id,),
        )
        case.geofences.append(fence)
        case.modes[op_id] = Mode.COMMAND
        cmd = Command(kind=kind, operation_id=op_id)
        d = d.merge(
            em.issue(
                case,
                op_id,
                now,
                command=cmd,
                geofence=fence,
                reason=f"{t.kind.value}: suspend ({kind.value}) and keep others out",
            )
        )
        d = d.merge(
            Decision(
                geofences=(fence,),
                audit=(
                    em.audit(
                        now,
                        "decision",
                        t.id,
                        {
                            "reason": f"{t.kind.value}: suspend + dynamic geofence",
                            "command": kind.value,
                            "geofence": fence.id,
                            "radius_m": cfg.jamming_radius_m,
                            "band_m": cfg.jamming_band_m,
                            "duration_s": cfg.jamming_duration_s,
                        },
                    ),
                ),
            )
        )
        d = d.merge(_reroute_affected(em, case, fence, snapshot, set(t.uas_ids)))
    return d


def link_loss(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision:
    now = snapshot.t_s
    cfg = em.config
    t = case.threat
    d = Decision()
    for op_id in t.uas_ids:
        op = snapshot.operations.get(op_id)
        msg = f"{t.id}: link lost with {op_id}; temporary geofence around its predicted position"
        if t.position is not None:
            e, n = em.frame.point_to_local(t.position.lat_deg, t.position.lon_deg)
            z = t.position.alt_amsl_m
        elif op is not None:
            from gcs_utm.core.deconfliction.geometry import plan_to_local

            p = plan_to_local(op.plan, em.frame).position_at(now + cfg.link_loss_predict_s)
            e, n, z = float(p[0]), float(p[1]), float(p[2])
        else:
            d = d.merge(Decision(escalations=(f"{t.id}: link lost with unknown {op_id}",)))
            continue
        fence = _cylinder(
            em,
            f"em-{t.id}-{op_id}",
            e,
            n,
            z,
            cfg.link_loss_radius_m,
            cfg.link_loss_band_m,
            now,
            cfg.link_loss_duration_s,
            f"link loss of {op_id}",
            exempt=(op_id,),
        )
        case.geofences.append(fence)
        d = d.merge(
            Decision(
                geofences=(fence,),
                escalations=(msg,),
                audit=(em.audit(now, "decision", t.id, {"reason": msg, "geofence": fence.id}),),
            )
        )
        d = d.merge(_reroute_affected(em, case, fence, snapshot, set(t.uas_ids)))
    return d


def area(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision:
    now = snapshot.t_s
    t = case.threat
    if t.area is None:
        msg = f"{t.id}: {t.kind.value} without an area: {t.message}"
        return Decision(
            escalations=(msg,), audit=(em.audit(now, "escalation", t.id, {"reason": msg}),)
        )
    fence = replace(
        t.area,
        kind=GeofenceKind.DYNAMIC,
        start_t_s=t.area.start_t_s if t.area.start_t_s is not None else now,
        end_t_s=t.area.end_t_s if t.area.end_t_s is not None else now + em.config.alert_duration_s,
        reason=t.area.reason or t.message or t.kind.value,
        source=t.area.source or ACTOR,
    )
    case.geofences.append(fence)
    d = Decision(
        geofences=(fence,),
        audit=(em.audit(now, "decision", t.id, {"reason": f"alert area -> geofence {fence.id}"}),),
    )
    return d.merge(_reroute_affected(em, case, fence, snapshot, set()))
