"""Sans-IO codec of the MQTT interface: topics, JSON bytes <-> typed messages.

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
    in   P/surveillance/adsb              adsb             surveillance provider
    in   P/authority/alerts               airspace_alert   fire brigade / authority
    out  P/operators/<op>/alerts          alert            threats for that operator's UAS
    out  P/operators/<op>/recommendations recommendation   alternative plans (QoS 1)
    out  P/operators/<op>/status          recommendation_status (QoS 1)
    out  P/operators/<op>/errors          error            errors caused by that operator
    out  P/alerts                         alert            alerts for everyone
    out  P/geofences                      geofences        retained: all active geofences
    out  P/geofences/events               geofence_event   created / removed (QoS 1)
    out  P/traffic                        traffic          tracks (QoS 0, rate limited)
    out  P/errors                         error            every error
    out  P/bridge                         bridge_status    retained online, last will offline
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from functools import cache
from importlib import resources
from typing import Any

import jsonschema
from referencing import Registry, Resource

from gcs_utm.messages import HazardReport, PilotAnswer, PilotDecision
from gcs_utm.model import (
    Alternative,
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
    Recommendation,
    RecommendationId,
    RecommendationState,
    SysId,
    Threat,
    ThreatKind,
    Track,
    VehicleKind,
    Waypoint4D,
    normalise_icao24,
)

SCHEMA_VERSION = 1
MAX_PAYLOAD_BYTES = 1_048_576
"""Larger payloads are refused before parsing: the largest legitimate message (a flight plan
of 10,000 waypoints) is about 800 kB."""

INBOUND_TYPES = (
    "rpa_state",
    "adsb",
    "flight_status",
    "flight_plan",
    "pilot_answer",
    "airspace_alert",
)
OUTBOUND_TYPES = (
    "alert",
    "recommendation",
    "recommendation_status",
    "geofences",
    "geofence_event",
    "traffic",
    "error",
    "bridge_status",
)
MESSAGE_TYPES = INBOUND_TYPES + OUTBOUND_TYPES

_OPERATOR_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


class MqttMessageError(ValueError):
    """A message that cannot be accepted: ``topic`` it came on, ``field`` (dotted path, ``""``
    for the whole message) and ``reason``."""

    def __init__(self, topic: str, field: str, reason: str) -> None:
        super().__init__(f"{topic}: {field or '<message>'}: {reason}")
        self.topic = topic
        self.field = field
        self.reason = reason


# --------------------------------------------------------------------------------------------
# Topics


class InboundKind(Enum):
    RPA_STATE = "rpa_state"
    FLIGHT_PLAN = "flight_plan"
    FLIGHT_STATUS = "flight_status"
    PILOT_ANSWER = "pilot_answer"
    ADSB = "adsb"
    AIRSPACE_ALERT = "airspace_alert"


OUTBOUND_OPERATOR_LEAVES = frozenset({"alerts", "recommendations", "status", "errors"})
"""Leaves the UTM itself publishes under ``operators/<op>/``: the ``operators/+/+``
subscription sees them come back, and they are ignored (never answered with an error, which
would loop)."""

_OPERATOR_SUFFIX = {
    "state": InboundKind.RPA_STATE,
    "flight_plans": InboundKind.FLIGHT_PLAN,
    "flight_status": InboundKind.FLIGHT_STATUS,
    "answers": InboundKind.PILOT_ANSWER,
}


def valid_operator(name: str) -> bool:
    """Operator names are topic levels and broker user names: no ``/``, ``+``, ``#``."""
    return bool(_OPERATOR_RE.match(name))


@dataclass(frozen=True, slots=True)
class Topics:
    """The topic names under one prefix."""

    prefix: str = "gcs_utm"

    def operator(self, operator: str, leaf: str) -> str:
        if not valid_operator(operator):
            raise ValueError(f"operator name {operator!r} is not a valid topic level")
        return f"{self.prefix}/operators/{operator}/{leaf}"

    def state(self, operator: str) -> str:
        return self.operator(operator, "state")

    def flight_plans(self, operator: str) -> str:
        return self.operator(operator, "flight_plans")

    def flight_status(self, operator: str) -> str:
        return self.operator(operator, "flight_status")

    def answers(self, operator: str) -> str:
        return self.operator(operator, "answers")

    def alerts_for(self, operator: str) -> str:
        return self.operator(operator, "alerts")

    def recommendations(self, operator: str) -> str:
        return self.operator(operator, "recommendations")

    def status(self, operator: str) -> str:
        return self.operator(operator, "status")

    def errors_for(self, operator: str) -> str:
        return self.operator(operator, "errors")

    @property
    def adsb(self) -> str:
        return f"{self.prefix}/surveillance/adsb"

    @property
    def airspace_alerts(self) -> str:
        return f"{self.prefix}/authority/alerts"

    @property
    def alerts(self) -> str:
        return f"{self.prefix}/alerts"

    @property
    def geofences(self) -> str:
        return f"{self.prefix}/geofences"

    @property
    def geofence_events(self) -> str:
        return f"{self.prefix}/geofences/events"

    @property
    def traffic(self) -> str:
        return f"{self.prefix}/traffic"

    @property
    def errors(self) -> str:
        return f"{self.prefix}/errors"

    @property
    def bridge(self) -> str:
        return f"{self.prefix}/bridge"

    def subscriptions(self) -> tuple[str, ...]:
        """Topic filters the UTM subscribes to. ``operators/+/+`` (not only the four
        leaves) so a message on an unknown leaf gets an error instead of silence."""
        return (
            f"{self.prefix}/operators/+/+",
            f"{self.prefix}/surveillance/+",
            f"{self.prefix}/authority/+",
        )

    def is_own_output(self, topic: str) -> bool:
        """True for an operator topic the UTM publishes on (echo of its own output)."""
        parts = topic.split("/")
        return self.operator_of(topic) is not None and parts[-1] in OUTBOUND_OPERATOR_LEAVES

    def classify(self, topic: str) -> tuple[InboundKind, str | None]:
        """Map an inbound topic to its kind and operator (None for non-operator topics);
        raise :class:`MqttMessageError` for a topic that is not an inbound operation."""
        head = f"{self.prefix}/"
        if not topic.startswith(head):
            raise MqttMessageError(topic, "", "topic outside the gcs-utm prefix")
        parts = topic[len(head) :].split("/")
        if len(parts) == 3 and parts[0] == "operators":
            operator, leaf = parts[1], parts[2]
            if not valid_operator(operator):
                raise MqttMessageError(topic, "", f"invalid operator name {operator!r}")
            kind = _OPERATOR_SUFFIX.get(leaf)
            if kind is None:
                raise MqttMessageError(
                    topic,
                    "",
                    f"unknown operation {leaf!r}; expected one of {sorted(_OPERATOR_SUFFIX)}",
                )
            return kind, operator
        if topic == self.adsb:
            return InboundKind.ADSB, None
        if topic == self.airspace_alerts:
            return InboundKind.AIRSPACE_ALERT, None
        raise MqttMessageError(topic, "", "unknown operation (no inbound message on this topic)")

    def operator_of(self, topic: str) -> str | None:
        """The operator a topic belongs to, or None."""
        parts = topic.split("/")
        head = self.prefix.split("/")
        n = len(head)
        if len(parts) > n + 1 and parts[:n] == head and parts[n] == "operators":
            op = parts[n + 1]
            return op if valid_operator(op) else None
        return None


# --------------------------------------------------------------------------------------------
# Schemas


@cache
def _registry() -> tuple[Registry[Any], dict[str, dict[str, Any]]]:
    folder = resources.files("adapters.mqtt") / "schemas"
    schemas: dict[str, dict[str, Any]] = {}
    resources_: list[tuple[str, Resource[Any]]] = []
    for name in ("common", *MESSAGE_TYPES):
        contents = json.loads((folder / f"{name}.json").read_text(encoding="utf-8"))
        schemas[name] = contents
        resources_.append((contents["$id"], Resource.from_contents(contents)))
    registry: Registry[Any] = Registry().with_resources(resources_)
    return registry, schemas


@cache
def _validator(message_type: str) -> Any:
    registry, schemas = _registry()
    schema = schemas[message_type]
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema, registry=registry, format_checker=cls.FORMAT_CHECKER)


def schema(message_type: str) -> dict[str, Any]:
    """The JSON Schema of ``message_type`` (a copy of the packaged file's contents)."""
    if message_type not in MESSAGE_TYPES:
        raise KeyError(message_type)
    return json.loads(json.dumps(_registry()[1][message_type]))  # type: ignore[no-any-return]


def _path(error: Any) -> str:
    return ".".join(str(p) for p in error.absolute_path)


def validate(message_type: str, obj: object, topic: str = "") -> None:
    """Raise :class:`MqttMessageError` when ``obj`` violates the schema of ``message_type``.
    The reported error is the most specific one (``jsonschema.exceptions.best_match``)."""
    validator = _validator(message_type)
    error = jsonschema.exceptions.best_match(validator.iter_errors(obj))
    if error is None:
        return
    # best_match may descend into the wrong oneOf branch: go back to the top error and take
    # the branch that was meant (the one whose "shape"-like const matched), e.g. report a
    # circle without a radius rather than "'polygon' was expected"
    while error.parent is not None:
        error = error.parent
    while error.context:
        branches: dict[object, list[Any]] = {}
        for e in error.context:
            branches.setdefault(e.relative_schema_path[0], []).append(e)
        meant = [b for b in branches.values() if not any(e.validator == "const" for e in b)]
        pool = meant[0] if len(meant) == 1 else list(error.context)
        error = max(pool, key=lambda e: len(e.absolute_path))
    field = _path(error)
    if error.validator == "required" and isinstance(error.instance, dict):
        missing = [k for k in error.validator_value if k not in error.instance]
        if missing:
            field = f"{field}.{missing[0]}" if field else str(missing[0])
    raise MqttMessageError(topic, field, _short(error.message))


def _short(text: str, limit: int = 200) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not valid JSON")


def parse_json(topic: str, payload: bytes | bytearray | str) -> object:
    """Strict JSON: UTF-8, no NaN/Infinity, at most :data:`MAX_PAYLOAD_BYTES`."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MqttMessageError(
            topic, "", f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}"
        )
    try:
        text = payload if isinstance(payload, str) else bytes(payload).decode("utf-8")
        return json.loads(text, parse_constant=_reject_constant)
    except UnicodeDecodeError as exc:
        raise MqttMessageError(topic, "", f"payload is not UTF-8: {exc.reason}") from exc
    except RecursionError as exc:
        raise MqttMessageError(topic, "", "JSON nested too deeply") from exc
    except ValueError as exc:  # json.JSONDecodeError and the NaN rejection
        raise MqttMessageError(topic, "", f"malformed JSON: {_short(str(exc))}") from exc


def dumps(obj: Mapping[str, object]) -> bytes:
    """Compact, valid JSON (raises ValueError on NaN/inf rather than emitting non-JSON)."""
    return json.dumps(obj, allow_nan=False, separators=(",", ":"), sort_keys=False).encode()


# --------------------------------------------------------------------------------------------
# Inbound messages


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
    RpaState | Measurement | FlightStatusReport | FlightPlanSubmission | PilotAnswer | HazardReport
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
    geometry = obj["geometry"]
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
        return Geofence(
            shape=GeofenceShape.CYLINDER,
            center=LatLon(lat_deg=float(c["lat_deg"]), lon_deg=float(c["lon_deg"])),
            radius_m=float(geometry["radius_m"]),
            **common,
        )
    return Geofence(
        shape=GeofenceShape.POLYGON,
        vertices=tuple(
            LatLon(lat_deg=float(v["lat_deg"]), lon_deg=float(v["lon_deg"]))
            for v in geometry["vertices"]
        ),
        **common,
    )


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
}


# --------------------------------------------------------------------------------------------
# Outbound messages


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
            else {"kind": cmd.kind.value, "target": _pos(cmd.target)},
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
            "topic": _short(topic),
            "field": _short(field),
            "reason": _short(reason, 500),
        }
    )


def encode_bridge_status(online: bool, t_s: float | None) -> bytes:
    return dumps({**_header("bridge_status"), "t_s": t_s, "online": online})
