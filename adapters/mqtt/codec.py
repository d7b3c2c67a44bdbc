"""Sans-IO codec of the MQTT interface: topics, JSON bytes <-> typed messages.

This module decodes inbound messages; it re-exports the rest of the codec, which lives by
responsibility in :mod:`adapters.mqtt.wire` (JSON, schemas, the error type),
:mod:`adapters.mqtt.topics` (topic names) and :mod:`adapters.mqtt.encode` (outbound).

Every incoming payload is parsed as strict JSON (no NaN/Infinity), validated against its JSON
Schema (``adapters/mqtt/schemas/<type>.json``, draft 2020-12) and converted to the shared model;
any failure is one :class:`MqttMessageError` naming the topic, the field (a JSON pointer-like
dotted path) and the reason. Outgoing messages are produced with ``json.dumps(allow_nan=False)``
so they are always valid JSON, and carry ``schema_version`` and ``type``.

Units follow the model: WGS84 degrees, metres AMSL, POSIX seconds (UTC), m/s.

Topic layout (``P`` is ``MqttConfig.topic_prefix``, ``<op>`` an operator name, which is also
its broker user name so the broker ACL can bind topics to identities)::

    in   P/operators/<op>/state           rpa_state        telemetry + GNSS integrity
    in   P/operators/<op>/flight_plans    flight_plan      plan submission
    in   P/operators/<op>/flight_status   flight_status    start / stop
    in   P/operators/<op>/answers         pilot_answer     accept / reject (QoS 1)
    in   P/operators/<op>/commands        operator_command hold / land / rtl / resume (QoS 1)
    in   P/surveillance/adsb              adsb             surveillance provider
    in   P/authority/alerts               airspace_alert   fire brigade / authority
    out  P/operators/<op>/alerts          alert            threats for that operator's UAS
    out  P/operators/<op>/recommendations recommendation   alternative plans (QoS 1)
    out  P/operators/<op>/status          recommendation_status, command_status (QoS 1)
    out  P/operators/<op>/errors          error            errors caused by that operator
    out  P/alerts                         alert            alerts for everyone
    out  P/geofences                      geofences        retained: all active geofences
    out  P/geofences/events               geofence_event   created / removed (QoS 1)
    out  P/traffic                        traffic          tracks (QoS 0, rate limited)
    out  P/errors                         error            every error
    out  P/bridge                         bridge_status    retained online, last will offline
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any

from adapters.mqtt.encode import (
    encode_alert,
    encode_bridge_status,
    encode_command_status,
    encode_error,
    encode_geofence_event,
    encode_geofences,
    encode_recommendation,
    encode_recommendation_status,
    encode_traffic,
    geofence_json,
)
from adapters.mqtt.topics import (
    OUTBOUND_OPERATOR_LEAVES,
    InboundKind,
    Topics,
    valid_operator,
)
from adapters.mqtt.wire import (
    INBOUND_TYPES,
    MAX_PAYLOAD_BYTES,
    MESSAGE_TYPES,
    OUTBOUND_TYPES,
    SCHEMA_VERSION,
    MqttMessageError,
    dumps,
    parse_json,
    schema,
    validate,
)
from gcs_utm.messages import HazardReport, PilotAnswer, PilotDecision
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
    Icao24,
    LatLon,
    Measurement,
    MeasurementSource,
    ModelError,
    Operation,
    OperationId,
    Position,
    RecommendationId,
    SysId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
    normalise_icao24,
)
from gcs_utm.validation import altitude_problem, latlon_problem, polygon_problem, radius_problem


@dataclass(frozen=True, slots=True, kw_only=True)
class OperatorCommandRequest:
    """An operator's hold / land / rtl / resume for one UAS (``operator`` from the topic)."""

    uas: str
    command: str
    request_id: str
    operator: str
    t_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CommandAck:
    """What became of an :class:`OperatorCommandRequest` (``outcome``: confirmed,
    acknowledged, failed or refused; ``mode`` the vehicle reports, "" when unknown)."""

    request_id: str
    uas: str
    command: str
    outcome: str
    reason: str = ""
    mode: str = ""


class FlightStatusKind(Enum):
    START = "start"
    STOP = "stop"


@dataclass(frozen=True, slots=True, kw_only=True)
class FlightStatusReport:
    """The remote pilot starts or stops the flight of an operation."""

    operation_id: OperationId
    status: FlightStatusKind
    t_s: float
    operator: str
    icao24: Icao24 | None = None
    plan_version: int | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class GnssIntegrity:
    """GNSS integrity and interference indicators of one RPA state message (paper §3: the
    jamming/spoofing detector runs on board and reports flags). Protection levels (PL),
    alert limits (AL) and position errors (PE) in metres."""

    hpl_m: float | None = None
    hal_m: float | None = None
    hpe_m: float | None = None
    vpl_m: float | None = None
    val_m: float | None = None
    vpe_m: float | None = None
    solution_mode: str = ""
    jamming: bool = False
    spoofing: bool = False
    anomalous_clock_drift: bool = False
    anomalous_pos_drift: bool = False
    cn0_dbhz: float | None = None
    received_power_dbm: float | None = None

    @property
    def integrity_lost(self) -> bool:
        """A protection level above its alert limit: the position can no longer be trusted
        to the level the operation needs (standard RAIM definition)."""
        h = self.hpl_m is not None and self.hal_m is not None and self.hpl_m > self.hal_m
        v = self.vpl_m is not None and self.val_m is not None and self.vpl_m > self.val_m
        return h or v


@dataclass(frozen=True, slots=True, kw_only=True)
class RpaState:
    """One RPA state message: the position measurement, attitude, and GNSS integrity.
    ``hazards`` are the threats its indicators report (jamming, spoofing, integrity loss)."""

    measurement: Measurement
    operator: str
    yaw_deg: float | None = None
    pitch_deg: float | None = None
    roll_deg: float | None = None
    ground_speed_mps: float | None = None
    gnss: GnssIntegrity | None = None

    @property
    def hazards(self) -> tuple[HazardReport, ...]:
        if self.gnss is None:
            return ()
        m = self.measurement
        where = Position(lat_deg=m.lat_deg, lon_deg=m.lon_deg, alt_amsl_m=m.alt_amsl_m)
        out: list[HazardReport] = []

        def add(kind: ThreatKind, message: str) -> None:
            out.append(
                HazardReport(
                    kind=kind,
                    t_s=m.capture_t_s,
                    operation_id=m.operation_id,
                    sys_id=m.sys_id,
                    icao24=m.icao24,
                    position=where,
                    message=message,
                    source=f"mqtt:{self.operator}",
                )
            )

        g = self.gnss
        if g.jamming:
            add(ThreatKind.JAMMING_ATTACK, "RPA reports GNSS jamming")
        if g.spoofing:
            add(ThreatKind.SPOOFING_ATTACK, "RPA reports GNSS spoofing")
        if g.integrity_lost or g.anomalous_clock_drift or g.anomalous_pos_drift:
            signs = [
                name
                for name, on in (
                    ("protection level above alert limit", g.integrity_lost),
                    ("anomalous clock drift", g.anomalous_clock_drift),
                    ("anomalous position drift", g.anomalous_pos_drift),
                )
                if on
            ]
            add(ThreatKind.GNSS_DEGRADATION, "RPA reports " + ", ".join(signs))
        return tuple(out)


@dataclass(frozen=True, slots=True, kw_only=True)
class FlightPlanSubmission:
    """A plan filed over MQTT: enough to build an :class:`Operation` (``to_operation``).
    Defaults for absent fields are the caller's (the USM's) choice."""

    operation_id: OperationId
    operator: str
    plan: FlightPlan
    t_s: float
    icao24: Icao24 | None = None
    sys_id: SysId | None = None
    vehicle_kind: VehicleKind | None = None
    autopilot: Autopilot | None = None
    priority: int | None = None
    cruise_speed_mps: float | None = None
    flight_geometry_m: float | None = None
    operational_volume_m: float | None = None
    conops: str = ""
    home: Position | None = None

    def to_operation(
        self,
        *,
        default_priority: int = 1,
        default_vehicle_kind: VehicleKind = VehicleKind.MULTIROTOR,
        default_cruise_speed_mps: float = 10.0,
        default_flight_geometry_m: float = 10.0,
        default_operational_volume_m: float = 30.0,
    ) -> Operation:
        """The operation this submission describes (state PLANNED); raises
        :class:`ModelError` when the values are inconsistent (e.g. volume < geometry)."""
        return Operation(
            id=self.operation_id,
            icao24=self.icao24,
            sys_id=self.sys_id,
            priority=default_priority if self.priority is None else self.priority,
            plan=self.plan,
            vehicle_kind=self.vehicle_kind or default_vehicle_kind,
            cruise_speed_mps=self.cruise_speed_mps or default_cruise_speed_mps,
            flight_geometry_m=self.flight_geometry_m or default_flight_geometry_m,
            operational_volume_m=self.operational_volume_m or default_operational_volume_m,
            conops=self.conops,
            home=self.home,
            autopilot=self.autopilot or Autopilot.PX4,
            operator=self.operator,
        )


Inbound = (
    RpaState
    | Measurement
    | FlightStatusReport
    | FlightPlanSubmission
    | PilotAnswer
    | HazardReport
    | OperatorCommandRequest
)


def _opt_float(obj: Mapping[str, Any], key: str) -> float | None:
    value = obj.get(key)
    return None if value is None else float(value)


def _icao(obj: Mapping[str, Any], topic: str, key: str = "icao24") -> Icao24 | None:
    value = obj.get(key)
    if value is None:
        return None
    try:
        return normalise_icao24(str(value))
    except ModelError as exc:
        raise MqttMessageError(topic, key, exc.message) from exc


def _waypoints(items: Sequence[Mapping[str, Any]]) -> tuple[Waypoint4D, ...]:
    return tuple(
        Waypoint4D(
            lat_deg=float(w["lat_deg"]),
            lon_deg=float(w["lon_deg"]),
            alt_amsl_m=float(w["alt_amsl_m"]),
            t_s=float(w["t_s"]),
        )
        for w in items
    )


def _geofence_from(obj: Mapping[str, Any], geofence_id: str, **extra: Any) -> Geofence:
    """A geofence from a schema-valid object, checked by the rules every input shares
    (:mod:`gcs_utm.validation`): a polygon must be a simple ring (a bow-tie is refused), the
    radius and altitudes plausible. A problem is a ModelError naming the field."""
    geometry = obj["geometry"]
    for key in ("min_alt_amsl_m", "max_alt_amsl_m"):
        _check(key, altitude_problem(float(obj[key])))
    common: dict[str, Any] = {
        "id": GeofenceId(geofence_id),
        "min_alt_amsl_m": float(obj["min_alt_amsl_m"]),
        "max_alt_amsl_m": float(obj["max_alt_amsl_m"]),
        "start_t_s": _opt_float(obj, "start_t_s"),
        "end_t_s": _opt_float(obj, "end_t_s"),
        **extra,
    }
    if geometry["shape"] == "circle":
        c = geometry["center"]
        center = LatLon(lat_deg=float(c["lat_deg"]), lon_deg=float(c["lon_deg"]))
        _check("geometry.center", latlon_problem(center.lat_deg, center.lon_deg))
        _check("geometry.radius_m", radius_problem(float(geometry["radius_m"])))
        return Geofence(
            shape=GeofenceShape.CYLINDER,
            center=center,
            radius_m=float(geometry["radius_m"]),
            **common,
        )
    vertices = tuple(
        LatLon(lat_deg=float(v["lat_deg"]), lon_deg=float(v["lon_deg"]))
        for v in geometry["vertices"]
    )
    _check("geometry.vertices", polygon_problem([(v.lat_deg, v.lon_deg) for v in vertices]))
    return Geofence(shape=GeofenceShape.POLYGON, vertices=vertices, **common)


def _check(field: str, problem: str | None) -> None:
    if problem is not None:
        raise ModelError("geofence", field, problem)


def decode_geofence(obj: Mapping[str, Any], topic: str = "") -> Geofence:
    """A geofence object of the ``common.json#/$defs/geofence`` shape (already validated)."""
    try:
        return _geofence_from(
            obj,
            str(obj["id"]),
            kind=GeofenceKind(obj.get("kind", "static")),
            reason=str(obj.get("reason", "")),
            source=str(obj.get("source", "")),
        )
    except ModelError as exc:
        raise MqttMessageError(topic, exc.field_name, exc.message) from exc


def decode(
    topics: Topics, topic: str, payload: bytes | bytearray | str, receipt_t_s: float
) -> Inbound:
    """Decode one inbound message (any of the inbound topics) or raise
    :class:`MqttMessageError`. The operator is taken from the topic, never from the payload:
    the broker ACL binds the topic to the authenticated user."""
    kind, operator = topics.classify(topic)
    obj = parse_json(topic, payload)
    if isinstance(obj, dict) and "type" in obj and obj["type"] != kind.value:
        raise MqttMessageError(
            topic, "type", f"a {obj['type']!r} message on a {kind.value!r} topic"
        )
    validate(kind.value, obj, topic)
    assert isinstance(obj, dict)
    try:
        return _DECODERS[kind](obj, topic, operator or "", receipt_t_s)
    except ModelError as exc:
        raise MqttMessageError(topic, exc.field_name, exc.message) from exc


def _decode_rpa_state(
    obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float
) -> RpaState:
    ch = _opt_float(obj, "covariance_h_m2")
    cv = _opt_float(obj, "covariance_v_m2")
    vel = obj.get("vel_ned_mps")
    sys_id = obj.get("sys_id")
    op_id = obj.get("operation_id")
    m = Measurement(
        source=MeasurementSource.MQTT,
        capture_t_s=float(obj["t_s"]),
        receipt_t_s=receipt_t_s,
        lat_deg=float(obj["lat_deg"]),
        lon_deg=float(obj["lon_deg"]),
        alt_amsl_m=float(obj["alt_amsl_m"]),
        vel_ned_mps=None if vel is None else (float(vel[0]), float(vel[1]), float(vel[2])),
        eph_m=None if ch is None else math.sqrt(ch),
        epv_m=None if cv is None else math.sqrt(cv),
        sys_id=None if sys_id is None else SysId(int(sys_id)),
        icao24=_icao(obj, topic),
        operation_id=None if op_id is None else OperationId(str(op_id)),
        link=f"mqtt:{operator}",
    )
    g = obj.get("gnss")
    gnss = None
    if g is not None:
        gnss = GnssIntegrity(
            hpl_m=_opt_float(g, "hpl_m"),
            hal_m=_opt_float(g, "hal_m"),
            hpe_m=_opt_float(g, "hpe_m"),
            vpl_m=_opt_float(g, "vpl_m"),
            val_m=_opt_float(g, "val_m"),
            vpe_m=_opt_float(g, "vpe_m"),
            solution_mode=str(g.get("solution_mode", "")),
            jamming=bool(g.get("jamming", False)),
            spoofing=bool(g.get("spoofing", False)),
            anomalous_clock_drift=bool(g.get("anomalous_clock_drift", False)),
            anomalous_pos_drift=bool(g.get("anomalous_pos_drift", False)),
            cn0_dbhz=_opt_float(g, "cn0_dbhz"),
            received_power_dbm=_opt_float(g, "received_power_dbm"),
        )
    return RpaState(
        measurement=m,
        operator=operator,
        yaw_deg=_opt_float(obj, "yaw_deg"),
        pitch_deg=_opt_float(obj, "pitch_deg"),
        roll_deg=_opt_float(obj, "roll_deg"),
        ground_speed_mps=_opt_float(obj, "ground_speed_mps"),
        gnss=gnss,
    )


def _decode_adsb(obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float) -> Measurement:
    vel: tuple[float, float, float] | None = None
    gs = _opt_float(obj, "ground_speed_mps")
    hdg = _opt_float(obj, "heading_deg")
    if gs is not None and hdg is not None:
        vr = _opt_float(obj, "vertical_rate_mps") or 0.0
        rad = math.radians(hdg)
        vel = (gs * math.cos(rad), gs * math.sin(rad), -vr)
    return Measurement(
        source=MeasurementSource.ADSB,
        capture_t_s=float(obj["t_s"]),
        receipt_t_s=receipt_t_s,
        lat_deg=float(obj["lat_deg"]),
        lon_deg=float(obj["lon_deg"]),
        alt_amsl_m=float(obj["alt_amsl_m"]),
        vel_ned_mps=vel,
        eph_m=_opt_float(obj, "eph_m"),
        icao24=_icao(obj, topic),
        link="mqtt:adsb",
        callsign=str(obj.get("callsign", "")).strip(),
    )


def _decode_flight_status(
    obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float
) -> FlightStatusReport:
    pv = obj.get("plan_version")
    return FlightStatusReport(
        operation_id=OperationId(str(obj["operation_id"])),
        status=FlightStatusKind(obj["status"]),
        t_s=float(obj["t_s"]),
        operator=operator,
        icao24=_icao(obj, topic),
        plan_version=None if pv is None else int(pv),
    )


def _decode_flight_plan(
    obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float
) -> FlightPlanSubmission:
    op_id = OperationId(str(obj["operation_id"]))
    plan = FlightPlan(
        operation_id=op_id,
        version=0,
        waypoints=_waypoints(obj["waypoints"]),
        created_t_s=float(obj["t_s"]),
        reason="filed over MQTT",
    )
    home = obj.get("home")
    sys_id = obj.get("sys_id")
    vk = obj.get("vehicle_kind")
    ap = obj.get("autopilot")
    prio = obj.get("priority")
    return FlightPlanSubmission(
        operation_id=op_id,
        operator=operator,
        plan=plan,
        t_s=float(obj["t_s"]),
        icao24=_icao(obj, topic),
        sys_id=None if sys_id is None else SysId(int(sys_id)),
        vehicle_kind=None if vk is None else VehicleKind(vk),
        autopilot=None if ap is None else Autopilot(ap),
        priority=None if prio is None else int(prio),
        cruise_speed_mps=_opt_float(obj, "cruise_speed_mps"),
        flight_geometry_m=_opt_float(obj, "flight_geometry_m"),
        operational_volume_m=_opt_float(obj, "operational_volume_m"),
        conops=str(obj.get("conops", "")),
        home=None
        if home is None
        else Position(
            lat_deg=float(home["lat_deg"]),
            lon_deg=float(home["lon_deg"]),
            alt_amsl_m=float(home["alt_amsl_m"]),
        ),
    )


def _decode_pilot_answer(
    obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float
) -> PilotAnswer:
    idx = obj.get("alternative_index")
    return PilotAnswer(
        recommendation_id=RecommendationId(str(obj["recommendation_id"])),
        version=int(obj["version"]),
        decision=PilotDecision(obj["decision"]),
        t_s=float(obj["t_s"]),
        operator=operator,
        source="mqtt",
        alternative_index=None if idx is None else int(idx),
    )


def _decode_operator_command(
    obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float
) -> OperatorCommandRequest:
    return OperatorCommandRequest(
        uas=str(obj["uas"]),
        command=str(obj["command"]),
        request_id=str(obj["id"]),
        operator=operator,
        t_s=float(obj.get("t_s", receipt_t_s)),
    )


def _decode_airspace_alert(
    obj: dict[str, Any], topic: str, operator: str, receipt_t_s: float
) -> HazardReport:
    category = str(obj["category"])
    alert_id = str(obj["alert_id"])
    name = str(obj.get("name", "")) or category
    area = _geofence_from(
        obj,
        f"alert:{alert_id}",
        kind=GeofenceKind.DYNAMIC,
        reason=f"{category}: {name}",
        source="mqtt:authority",
    )
    return HazardReport(
        kind=ThreatKind.ALERT_WARNING,
        t_s=float(obj["t_s"]),
        area=area,
        message=str(obj.get("message", "")) or f"{category} alert {name}",
        source=f"mqtt:authority:{category}",
    )


_DECODERS: dict[InboundKind, Callable[[dict[str, Any], str, str, float], Inbound]] = {
    InboundKind.RPA_STATE: _decode_rpa_state,
    InboundKind.ADSB: _decode_adsb,
    InboundKind.FLIGHT_STATUS: _decode_flight_status,
    InboundKind.FLIGHT_PLAN: _decode_flight_plan,
    InboundKind.PILOT_ANSWER: _decode_pilot_answer,
    InboundKind.AIRSPACE_ALERT: _decode_airspace_alert,
    InboundKind.OPERATOR_COMMAND: _decode_operator_command,
}


__all__ = [
    "INBOUND_TYPES",
    "MAX_PAYLOAD_BYTES",
    "MESSAGE_TYPES",
    "OUTBOUND_OPERATOR_LEAVES",
    "OUTBOUND_TYPES",
    "SCHEMA_VERSION",
    "CommandAck",
    "FlightPlanSubmission",
    "FlightStatusKind",
    "FlightStatusReport",
    "GnssIntegrity",
    "InboundKind",
    "MqttMessageError",
    "OperatorCommandRequest",
    "RpaState",
    "Topics",
    "decode",
    "decode_geofence",
    "dumps",
    "encode_alert",
    "encode_bridge_status",
    "encode_command_status",
    "encode_error",
    "encode_geofence_event",
    "encode_geofences",
    "encode_recommendation",
    "encode_recommendation_status",
    "encode_traffic",
    "geofence_json",
    "parse_json",
    "schema",
    "valid_operator",
    "validate",
]
