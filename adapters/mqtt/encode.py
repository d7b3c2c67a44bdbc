"""Outbound messages of the MQTT interface: model objects -> JSON bytes that validate
against their schemas, each with ``schema_version`` and ``type``."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from adapters.mqtt.wire import SCHEMA_VERSION, dumps, short
from gcs_utm.core.emergency.wording import command_text, option_text, proposal_text, why_text
from gcs_utm.model import (
    Alternative,
    Geofence,
    GeofenceShape,
    Position,
    Recommendation,
    RecommendationId,
    RecommendationState,
    RemoteIdentity,
    Threat,
    Track,
    Waypoint4D,
)


def _header(message_type: str) -> dict[str, object]:
    return {"schema_version": SCHEMA_VERSION, "type": message_type}


def _wp(w: Waypoint4D) -> dict[str, object]:
    return {"lat_deg": w.lat_deg, "lon_deg": w.lon_deg, "alt_amsl_m": w.alt_amsl_m, "t_s": w.t_s}


def _pos(p: Position | None) -> dict[str, object] | None:
    if p is None:
        return None
    return {"lat_deg": p.lat_deg, "lon_deg": p.lon_deg, "alt_amsl_m": p.alt_amsl_m}


def geofence_json(g: Geofence) -> dict[str, object]:
    geometry: dict[str, object]
    if g.shape is GeofenceShape.CYLINDER:
        assert g.center is not None
        geometry = {
            "shape": "circle",
            "center": {"lat_deg": g.center.lat_deg, "lon_deg": g.center.lon_deg},
            "radius_m": g.radius_m,
        }
    else:
        geometry = {
            "shape": "polygon",
            "vertices": [{"lat_deg": v.lat_deg, "lon_deg": v.lon_deg} for v in g.vertices],
        }
    return {
        "id": g.id,
        "geometry": geometry,
        "min_alt_amsl_m": g.min_alt_amsl_m,
        "max_alt_amsl_m": g.max_alt_amsl_m,
        "start_t_s": g.start_t_s,
        "end_t_s": g.end_t_s,
        "kind": g.kind.value,
        "reason": g.reason,
        "source": g.source,
    }


def _alternative(a: Alternative) -> dict[str, object]:
    return {
        "maneuver": a.maneuver.value,
        "cost": a.cost,
        "risk": a.risk,
        "detail": a.detail,
        "text": option_text(a),
        "plan_version": None if a.plan is None else a.plan.version,
        "waypoints": [] if a.plan is None else [_wp(w) for w in a.plan.waypoints],
    }


def encode_alert(threat: Threat) -> bytes:
    return dumps(
        {
            **_header("alert"),
            "alert_id": threat.id,
            "kind": threat.kind.value,
            "status": threat.status.value,
            "operation_ids": list(threat.uas_ids),
            "detected_at_s": threat.detected_at_s,
            "predicted_event_at_s": threat.predicted_event_at_s,
            "updated_at_s": threat.updated_at_s,
            "geofence_id": threat.geofence_id,
            "intruder_id": threat.intruder_id,
            "closest_approach_m": threat.closest_approach_m,
            "closest_approach_t_s": threat.closest_approach_t_s,
            "position": _pos(threat.position),
            "area": None if threat.area is None else geofence_json(threat.area),
            "message": threat.message,
        }
    )


def encode_recommendation(rec: Recommendation) -> bytes:
    cmd = rec.command
    return dumps(
        {
            **_header("recommendation"),
            "recommendation_id": rec.id,
            "version": rec.version,
            "threat_id": rec.threat_id,
            "threat_kind": rec.threat_kind.value,
            "operation_id": rec.operation_id,
            "created_t_s": rec.created_t_s,
            "deadline_t_s": rec.deadline_t_s,
            "selected": None if rec.selected is None else _alternative(rec.selected),
            "alternatives": [_alternative(a) for a in rec.alternatives],
            "command": None
            if cmd is None
            else {"kind": cmd.kind.value, "target": _pos(cmd.target), "text": command_text(cmd)},
            "text": proposal_text(rec),
            "why": why_text(rec),
            "new_geofence": None if rec.new_geofence is None else geofence_json(rec.new_geofence),
            "reason": rec.reason,
        }
    )


def encode_recommendation_status(
    *,
    recommendation_id: RecommendationId,
    version: int,
    t_s: float,
    state: RecommendationState | None,
    reason: str = "",
    answer: Mapping[str, object] | None = None,
) -> bytes:
    """``answer`` (when this replies to a pilot answer) is
    ``{"outcome": accepted|duplicate|refused, "decision": accept|reject, "version": n}``."""
    return dumps(
        {
            **_header("recommendation_status"),
            "recommendation_id": recommendation_id,
            "version": version,
            "t_s": t_s,
            "state": None if state is None else state.value,
            "answer": None if answer is None else dict(answer),
            "reason": reason,
        }
    )


def encode_command_status(
    *, request_id: str, uas: str, command: str, t_s: float, outcome: str, reason: str, mode: str
) -> bytes:
    """The outcome of one operator command (``command_status``, on the status topic)."""
    return dumps(
        {
            **_header("command_status"),
            "id": request_id,
            "uas": uas,
            "command": command,
            "t_s": t_s,
            "outcome": outcome,
            "reason": reason,
            "mode": mode,
        }
    )


def encode_geofences(active: Iterable[Geofence], t_s: float) -> bytes:
    return dumps(
        {**_header("geofences"), "t_s": t_s, "geofences": [geofence_json(g) for g in active]}
    )


def encode_geofence_event(action: str, g: Geofence, t_s: float) -> bytes:
    if action not in ("created", "removed"):
        raise ValueError(f"action must be 'created' or 'removed', got {action!r}")
    return dumps(
        {**_header("geofence_event"), "t_s": t_s, "action": action, "geofence": geofence_json(g)}
    )


def _remote_id(rid: RemoteIdentity | None) -> dict[str, object] | None:
    """A track's Remote ID (docs/remote-id.md), null when none was heard."""
    if rid is None:
        return None
    return {
        "source": rid.source,
        "uas_id": rid.uas_id,
        "id_type": rid.id_type,
        "ua_type": rid.ua_type,
        "operator_id": rid.operator_id,
        "lat_deg": rid.lat_deg,
        "lon_deg": rid.lon_deg,
        "alt_m": rid.alt_m,
        "location_t_s": rid.location_t_s,
        "updated_t_s": rid.updated_t_s,
    }


def encode_traffic(tracks: Iterable[Track], t_s: float) -> bytes:
    return dumps(
        {
            **_header("traffic"),
            "t_s": t_s,
            "tracks": [
                {
                    "track_id": tr.id,
                    "t_s": tr.t_s,
                    "lat_deg": tr.lat_deg,
                    "lon_deg": tr.lon_deg,
                    "alt_amsl_m": tr.alt_amsl_m,
                    "vel_enu_mps": list(tr.vel_enu_mps),
                    "ground_speed_mps": tr.ground_speed_mps,
                    "position_sigma_m": tr.position_sigma_m,
                    "cooperative": tr.cooperative,
                    "operation_id": tr.operation_id,
                    "icao24": tr.icao24,
                    "stale": tr.stale,
                    "remote_id": _remote_id(tr.remote_id),
                }
                for tr in tracks
            ],
        }
    )


def encode_error(topic: str, field: str, reason: str, t_s: float) -> bytes:
    return dumps(
        {
            **_header("error"),
            "t_s": t_s,
            "topic": short(topic),
            "field": short(field),
            "reason": short(reason, 500),
        }
    )


def encode_bridge_status(online: bool, t_s: float | None) -> bytes:
    return dumps({**_header("bridge_status"), "t_s": t_s, "online": online})
