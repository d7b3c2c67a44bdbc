"""Typed domain model of the UTM (the paper's Tables 2 and 3 and what flows between modules).

Invariants:
- every dataclass is frozen; a change is a new object (``dataclasses.replace``);
- units are in field names: ``lat_deg``, ``alt_amsl_m``, ``t_s`` (POSIX seconds, UTC),
  ``radius_m``, ``speed_mps``; altitudes are AMSL unless the name says otherwise;
- identifiers are ``NewType`` strings or ints, never bare positional tuples.

Validation of user input happens in :mod:`gcs_utm.config` and :mod:`gcs_utm.scenario`; the
constructors here only check what would silently corrupt state (NaN, inverted bands).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, NewType

import numpy as np
import numpy.typing as npt

from gcs_utm.envelope import PerformanceEnvelope, implied

Icao24 = NewType("Icao24", str)
"""ICAO 24-bit address as six lower-case hex digits, e.g. ``"3c6444"``."""
SysId = NewType("SysId", int)
"""MAVLink system id (1..255)."""
OperationId = NewType("OperationId", str)
GeofenceId = NewType("GeofenceId", str)
ThreatId = NewType("ThreatId", str)
RecommendationId = NewType("RecommendationId", str)
TrackId = NewType("TrackId", str)
"""An operation id for cooperative UAS, ``"icao:<hex>"`` for intruders."""

FloatArray = npt.NDArray[np.float64]


class ModelError(ValueError):
    """A value that would corrupt the model; ``item`` and ``field`` say where."""

    def __init__(self, item: str, field_name: str, message: str) -> None:
        super().__init__(f"{item}: {field_name}: {message}")
        self.item = item
        self.field_name = field_name
        self.message = message


def _finite(item: str, **values: float | None) -> None:
    for name, value in values.items():
        if value is not None and not math.isfinite(value):
            raise ModelError(item, name, f"must be a finite number, got {value!r}")


def normalise_icao24(value: str) -> Icao24:
    """Return ``value`` as six lower-case hex digits or raise :class:`ModelError`."""
    text = value.strip().lower().removeprefix("0x")
    if len(text) != 6 or any(c not in "0123456789abcdef" for c in text):
        raise ModelError("icao24", "icao24", f"expected 6 hex digits, got {value!r}")
    return Icao24(text)


# --------------------------------------------------------------------------------------------
# Geometry and plans


@dataclass(frozen=True, slots=True, kw_only=True)
class LatLon:
    lat_deg: float
    lon_deg: float

    def __post_init__(self) -> None:
        _finite("point", lat_deg=self.lat_deg, lon_deg=self.lon_deg)
        if not -90.0 <= self.lat_deg <= 90.0:
            raise ModelError("point", "lat_deg", f"must be in [-90, 90], got {self.lat_deg}")
        if not -180.0 <= self.lon_deg <= 180.0:
            raise ModelError("point", "lon_deg", f"must be in [-180, 180], got {self.lon_deg}")


@dataclass(frozen=True, slots=True, kw_only=True)
class Position:
    """A WGS84 position with altitude above mean sea level."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float

    def __post_init__(self) -> None:
        LatLon(lat_deg=self.lat_deg, lon_deg=self.lon_deg)
        _finite("position", alt_amsl_m=self.alt_amsl_m)


@dataclass(frozen=True, slots=True, kw_only=True)
class Waypoint4D:
    """A flight-plan point: where (WGS84, AMSL) and when (POSIX seconds)."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    t_s: float

    def __post_init__(self) -> None:
        Position(lat_deg=self.lat_deg, lon_deg=self.lon_deg, alt_amsl_m=self.alt_amsl_m)
        _finite("waypoint", t_s=self.t_s)

    @property
    def position(self) -> Position:
        return Position(lat_deg=self.lat_deg, lon_deg=self.lon_deg, alt_amsl_m=self.alt_amsl_m)


# weakref_slot: caches keyed by the plan object forget it when it is freed (TD's PlanCache)
@dataclass(frozen=True, slots=True, kw_only=True, weakref_slot=True)
class FlightPlan:
    """A versioned 4D flight plan (paper Table 3). Times never go backwards."""

    operation_id: OperationId
    version: int
    waypoints: tuple[Waypoint4D, ...]
    created_t_s: float = 0.0
    reason: str = "filed"

    def __post_init__(self) -> None:
        if len(self.waypoints) < 1:
            raise ModelError(f"plan {self.operation_id}", "waypoints", "needs at least 1 point")
        for i in range(1, len(self.waypoints)):
            if self.waypoints[i].t_s < self.waypoints[i - 1].t_s:
                raise ModelError(
                    f"plan {self.operation_id}",
                    f"waypoints[{i}].t_s",
                    f"time goes backwards ({self.waypoints[i].t_s} < {self.waypoints[i - 1].t_s})",
                )

    @property
    def start_t_s(self) -> float:
        return self.waypoints[0].t_s

    @property
    def end_t_s(self) -> float:
        return self.waypoints[-1].t_s


class GeofenceShape(Enum):
    CYLINDER = "cylinder"
    POLYGON = "polygon"


class GeofenceKind(Enum):
    STATIC = "static"
    DYNAMIC = "dynamic"


@dataclass(frozen=True, slots=True, kw_only=True)
class Geofence:
    """A no-fly volume in 4D (paper Table 2).

    A cylinder uses ``center`` and ``radius_m``; a polygon uses ``vertices`` (at least three,
    not self-intersecting: checked by the scenario loader with shapely). The altitude band is
    AMSL. ``start_t_s``/``end_t_s`` bound the activation window; ``None`` means unbounded.
    """

    id: GeofenceId
    shape: GeofenceShape
    min_alt_amsl_m: float
    max_alt_amsl_m: float
    center: LatLon | None = None
    radius_m: float | None = None
    vertices: tuple[LatLon, ...] = ()
    start_t_s: float | None = None
    end_t_s: float | None = None
    kind: GeofenceKind = GeofenceKind.STATIC
    reason: str = ""
    source: str = ""
    exempt: tuple[OperationId, ...] = ()
    """Operations this geofence does not apply to: the jammed or lost UAS a dynamic geofence
    was drawn around is inside it by construction (it is suspended, not intruding)."""

    def __post_init__(self) -> None:
        item = f"geofence {self.id}"
        _finite(
            item,
            min_alt_amsl_m=self.min_alt_amsl_m,
            max_alt_amsl_m=self.max_alt_amsl_m,
            radius_m=self.radius_m,
            start_t_s=self.start_t_s,
            end_t_s=self.end_t_s,
        )
        if self.min_alt_amsl_m > self.max_alt_amsl_m:
            raise ModelError(item, "min_alt_amsl_m", "is above max_alt_amsl_m")
        if (
            self.start_t_s is not None
            and self.end_t_s is not None
            and self.start_t_s > self.end_t_s
        ):
            raise ModelError(item, "start_t_s", "is after end_t_s")
        if self.shape is GeofenceShape.CYLINDER:
            if self.center is None:
                raise ModelError(item, "center", "a cylinder needs a center")
            if self.radius_m is None or self.radius_m <= 0.0:
                raise ModelError(item, "radius_m", "a cylinder needs a positive radius")
        elif len(self.vertices) < 3:
            raise ModelError(item, "vertices", "a polygon needs at least 3 vertices")

    def applies_to(self, op_id: str) -> bool:
        return op_id not in self.exempt

    def active_at(self, t_s: float) -> bool:
        """True when the geofence is active at ``t_s`` (window bounds inclusive)."""
        if self.start_t_s is not None and t_s < self.start_t_s:
            return False
        return not (self.end_t_s is not None and t_s > self.end_t_s)


# --------------------------------------------------------------------------------------------
# Operations


class VehicleKind(Enum):
    MULTIROTOR = "multirotor"
    FIXED_WING = "fixed_wing"


class Autopilot(Enum):
    PX4 = "px4"
    ARDUPILOT = "ardupilot"
    UNKNOWN = "unknown"


class OperationState(Enum):
    PLANNED = "planned"
    ACTIVE = "active"
    SUSPENDED = "suspended"
    LANDED = "landed"
    ENDED = "ended"


def default_envelope(
    kind: VehicleKind, cruise_speed_mps: float, climb_rate_mps: float
) -> PerformanceEnvelope:
    """The envelope an operation's description implies (:func:`gcs_utm.envelope.implied`)."""
    return implied(kind is VehicleKind.FIXED_WING, cruise_speed_mps, climb_rate_mps)


@dataclass(frozen=True, slots=True, kw_only=True)
class Operation:
    """A UAS operation (paper Table 3). The plan is the current version; the store keeps all.

    ``priority``: larger is more important (it moves less in deconfliction).
    ``flight_geometry_m``: radius within which the UAS is conforming to its plan.
    ``operational_volume_m``: radius of the operational volume around the plan; between the
    two is the contingency volume.
    """

    id: OperationId
    icao24: Icao24 | None
    sys_id: SysId | None
    priority: int
    plan: FlightPlan
    vehicle_kind: VehicleKind
    cruise_speed_mps: float
    flight_geometry_m: float
    operational_volume_m: float
    conops: str = ""
    home: Position | None = None
    landing_sites: tuple[Position, ...] = ()
    state: OperationState = OperationState.PLANNED
    autopilot: Autopilot = Autopilot.PX4
    max_climb_rate_mps: float = 3.0
    min_alt_amsl_m: float | None = None
    max_alt_amsl_m: float | None = None
    endurance_s: float | None = None
    operator: str = "default"
    next_waypoint: int = 0
    envelope: PerformanceEnvelope | None = None
    """What the vehicle can fly; None: :func:`default_envelope` of its description."""

    def performance(self) -> PerformanceEnvelope:
        """The vehicle's envelope: the one given, else what its description implies."""
        if self.envelope is not None:
            return self.envelope
        return default_envelope(self.vehicle_kind, self.cruise_speed_mps, self.max_climb_rate_mps)

    def __post_init__(self) -> None:
        item = f"operation {self.id}"
        _finite(
            item,
            cruise_speed_mps=self.cruise_speed_mps,
            flight_geometry_m=self.flight_geometry_m,
            operational_volume_m=self.operational_volume_m,
        )
        if self.cruise_speed_mps <= 0.0:
            raise ModelError(item, "cruise_speed_mps", "must be positive")
        if self.flight_geometry_m <= 0.0:
            raise ModelError(item, "flight_geometry_m", "must be positive")
        if self.operational_volume_m < self.flight_geometry_m:
            raise ModelError(item, "operational_volume_m", "must be >= flight_geometry_m")
        if self.sys_id is not None and not 1 <= self.sys_id <= 255:
            raise ModelError(item, "sys_id", f"must be in 1..255, got {self.sys_id}")
        if self.plan.operation_id != self.id:
            raise ModelError(item, "plan.operation_id", "does not match the operation id")


# --------------------------------------------------------------------------------------------
# Measurements and tracks


class MeasurementSource(Enum):
    TELEMETRY = "telemetry"
    ADSB = "adsb"
    MQTT = "mqtt"

    # Members are singletons compared by identity, so identity hashing is consistent with
    # equality; Enum's own __hash__ is a Python-level call, and this one is hashed per
    # measurement on the receive path (source keys in the USM and the tracking service).
    __hash__ = object.__hash__


@dataclass(frozen=True, slots=True, kw_only=True)
class Measurement:
    """One position report. ``capture_t_s`` is when it was true (vehicle or record time mapped
    to UTC); ``receipt_t_s`` is when we got it. Decisions use capture time.

    Identity: at least one of ``operation_id``, ``sys_id`` (telemetry) or ``icao24`` (ADS-B).
    System ids are 8-bit, so ``vehicle`` (telemetry: ``host:port`` the vehicle was first heard
    from, empty for a recording) tells apart vehicles that share a system id on one link.
    ``vel_ned_mps`` is (north, east, down); ``eph_m``/``epv_m`` are 1-sigma accuracies when
    known (GNSS eph/epv, ADS-B NACp).
    """

    source: MeasurementSource
    capture_t_s: float
    receipt_t_s: float
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    vel_ned_mps: tuple[float, float, float] | None = None
    eph_m: float | None = None
    epv_m: float | None = None
    sys_id: SysId | None = None
    icao24: Icao24 | None = None
    operation_id: OperationId | None = None
    link: str = ""
    callsign: str = ""
    vehicle: str = ""


SlotSetter = Callable[[Any, Any], None]


def slot_setters(cls: type, names: tuple[str, ...]) -> tuple[SlotSetter, ...] | None:
    """The member-descriptor setters of ``cls``'s fields ``names``, in that order, or None
    unless ``cls`` is a slotted dataclass with exactly these fields and no ``__post_init__``.

    A frozen dataclass's generated ``__init__`` writes each field by keyword through
    ``object.__setattr__`` (about 4 us for 15 fields here). ``object.__new__(cls)`` followed
    by these setters builds an equal object (same fields, same values; equality and hashing
    are by fields) in about a third of that, for the few hot paths that build one object per
    message or per row. Callers fall back to the constructor when this returns None, so a
    changed class stays correct."""
    slots = getattr(cls, "__slots__", None)
    if (
        not dataclasses.is_dataclass(cls)
        or tuple(f.name for f in dataclasses.fields(cls)) != names
        or slots is None
        or set(slots) != set(names)
        or hasattr(cls, "__post_init__")
    ):
        return None
    return tuple(cls.__dict__[name].__set__ for name in names)


@dataclass(frozen=True, slots=True)
class LaneSource:
    """Who a :class:`PositionLane` entry comes from: a telemetry source (one vehicle component
    on one link), as a :class:`Measurement` of it would name it (``source`` TELEMETRY, no ICAO
    address, no operation id)."""

    sys_id: SysId
    link: str
    vehicle: str


LANE_STRIDE = 11
"""Numbers per :class:`PositionLane` entry: source index (an int), receipt_t_s, capture_t_s,
lon_deg, lat_deg, alt_amsl_m, v_north, v_east, v_down (m/s), eph_m, epv_m (nan: unknown)."""


class PositionLane:
    """Telemetry position reports in columns, without a :class:`Measurement` object each.

    The MAVLink receive path appends one entry of :data:`LANE_STRIDE` numbers per position
    report to ``values`` (a flat list: ``values.extend(entry)`` is the whole per-report cost);
    whoever owns the lane takes them in bursts (:meth:`take`). An entry means exactly the
    :class:`Measurement` :meth:`measurement` gives for it: ``sources[index]``'s identity,
    velocity present, and ``nan`` for an unknown ``eph_m``/``epv_m`` (None in a Measurement;
    telemetry never reports nan otherwise).

    ``sources`` only grows: an index stays valid for the life of the lane."""

    __slots__ = ("_index", "sources", "values")

    def __init__(self) -> None:
        self.values: list[float] = []
        self.sources: list[LaneSource] = []
        self._index: dict[LaneSource, int] = {}

    def register(self, source: LaneSource) -> int:
        """The index of ``source`` (the same index for an equal source)."""
        i = self._index.get(source)
        if i is None:
            i = self._index[source] = len(self.sources)
            self.sources.append(source)
        return i

    def take(self) -> list[float]:
        """The entries appended since the last take (a new list), and the lane emptied; the
        producers' bound ``values.extend`` stays valid."""
        out = self.values.copy()
        self.values.clear()
        return out

    def measurement(self, values: Sequence[float], at: int) -> Measurement:
        """The :class:`Measurement` that the entry starting at ``values[at]`` stands for."""
        (i, rcv, cap, lon, lat, alt, vn, ve, vd, eph, epv) = values[at : at + LANE_STRIDE]
        src = self.sources[int(i)]
        return Measurement(
            source=MeasurementSource.TELEMETRY,
            capture_t_s=cap,
            receipt_t_s=rcv,
            lat_deg=lat,
            lon_deg=lon,
            alt_amsl_m=alt,
            vel_ned_mps=(vn, ve, vd),
            eph_m=None if math.isnan(eph) else eph,
            epv_m=None if math.isnan(epv) else epv,
            sys_id=src.sys_id,
            link=src.link,
            vehicle=src.vehicle,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class RemoteIdentity:
    """What a UAS's Remote ID (ASTM F3411 / OpenDroneID) says of it (docs/remote-id.md).
    ``source`` names the Remote ID record: ``sysid:<n>`` (what vehicle n reports of itself)
    or ``rid:<id_or_mac hex>`` (an aircraft a vehicle's receiver heard)."""

    source: str
    uas_id: str = ""  # "" until a Basic ID is heard
    id_type: str = ""  # F3411 ID type name (SERIAL_NUMBER, CAA_REGISTRATION_ID, ...)
    ua_type: str = ""  # F3411 UA type name (HELICOPTER_OR_MULTIROTOR, AEROPLANE, ...)
    operator_id: str = ""
    lat_deg: float | None = None  # the last Remote ID Location (None: none heard yet)
    lon_deg: float | None = None
    alt_m: float | None = None  # its geodetic (WGS84) altitude, else pressure altitude
    location_t_s: float | None = None  # when that Location was received
    updated_t_s: float = 0.0  # when any of this last changed


@dataclass(frozen=True, slots=True, kw_only=True)
class Track:
    """The filtered state of one UAS or intruder at ``t_s``.

    ``east_m``/``north_m`` are in the airspace's local UTM frame; ``cov`` is the 6x6 state
    covariance over (east, north, up, v_east, v_north, v_up).
    """

    id: TrackId
    t_s: float
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    east_m: float
    north_m: float
    vel_enu_mps: tuple[float, float, float]
    position_sigma_m: float
    cooperative: bool
    operation_id: OperationId | None = None
    icao24: Icao24 | None = None
    stale: bool = False
    updates: int = 0
    next_waypoint: int | None = None
    # the last accepted measurement's time when ``t_s`` is later (a track propagated to a
    # snapshot's time: dead-reckoned for ``t_s - measured_t_s``); None: measured at ``t_s``
    measured_t_s: float | None = None
    # set on the snapshots the views, MQTT and the store get (adapters/remoteid/tracks.py),
    # never by the tracker
    remote_id: RemoteIdentity | None = None

    @property
    def ground_speed_mps(self) -> float:
        return math.hypot(self.vel_enu_mps[0], self.vel_enu_mps[1])


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class PredictedTrajectories:
    """Predicted 4D trajectories of N tracks at ``t_s``: one (N, steps, 4) array of
    (east_m, north_m, alt_amsl_m, t_s) and one (N, steps) array of 1-sigma radii in metres.
    Row i belongs to ``track_ids[i]``."""

    t_s: float
    track_ids: tuple[TrackId, ...]
    points: FloatArray
    sigma_m: FloatArray


# --------------------------------------------------------------------------------------------
# Threats, alternatives, recommendations, commands


class ThreatKind(Enum):
    LOSS_OF_SEPARATION = "LOSS_OF_SEPARATION"
    GEOFENCE_INTRUSION = "GEOFENCE_INTRUSION"
    GEOFENCE_CONFLICT = "GEOFENCE_CONFLICT"
    UAS_OUT_OV = "UAS_OUT_OV"
    UAS_IN_CV = "UAS_IN_CV"
    JAMMING_ATTACK = "JAMMING_ATTACK"
    SPOOFING_ATTACK = "SPOOFING_ATTACK"  # the vehicle's own GNSS is spoofed (it says so)
    # a second sender on a MAVLink link claims a system id bound to a vehicle: its frames are
    # dropped; the real vehicle is not affected (two vehicles on one sysid, a stray sender)
    SYSID_CONFLICT = "SYSID_CONFLICT"
    GNSS_DEGRADATION = "GNSS_DEGRADATION"
    LACK_OF_BATTERY = "LACK_OF_BATTERY"
    TECHNICAL_FAILURE = "TECHNICAL_FAILURE"
    COMMUNICATION_FAILURE = "COMMUNICATION_FAILURE"
    ALERT_WARNING = "ALERT_WARNING"
    INTRUDER = "INTRUDER"
    # what a UAS broadcasts as Remote ID disagrees with its telemetry (position, identity)
    REMOTE_ID_MISMATCH = "REMOTE_ID_MISMATCH"


class ThreatStatus(Enum):
    OPEN = "open"
    UPDATED = "updated"
    CLOSED = "closed"


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class Threat:
    """A hazard for one or more UAS. A persisting conflict keeps its ``id`` and is updated.

    ``snapshot`` is the prediction Monitoring computed it on, so EM/TD decide on the same data.
    ``area`` is the geofence an alert asks to create (wildfire, jamming), if any.
    """

    id: ThreatId
    kind: ThreatKind
    uas_ids: tuple[OperationId, ...]
    detected_at_s: float
    predicted_event_at_s: float | None = None
    geofence_id: GeofenceId | None = None
    intruder_id: TrackId | None = None
    status: ThreatStatus = ThreatStatus.OPEN
    closest_approach_t_s: float | None = None
    closest_approach_m: float | None = None
    horizontal_m: float | None = None
    vertical_m: float | None = None
    position: Position | None = None
    area: Geofence | None = None
    message: str = ""
    snapshot: PredictedTrajectories | None = None
    updated_at_s: float | None = None


class Maneuver(Enum):
    GO_UP = "go_up"
    GO_DOWN = "go_down"
    GO_LEFT = "go_left"
    GO_RIGHT = "go_right"
    DELAY = "delay"
    SPEED_CHANGE = "speed_change"
    REROUTE = "reroute"
    ESCAPE = "escape"
    DIRECT_TO_GOAL = "direct_to_goal"
    BACK_TO_PLAN = "back_to_plan"
    NEXT_WAYPOINT = "next_waypoint"
    RETURN_HOME = "return_home"
    LANDING_SITE = "landing_site"
    KEEP_PLAN = "keep_plan"
    HOLD = "hold"
    LAND = "land"
    VERTICAL_AVOIDANCE = "vertical_avoidance"
    MOVE_END = "move_end"  # a new end point away from traffic (core/emergency/endpoint.py)


@dataclass(frozen=True, slots=True, kw_only=True)
class Alternative:
    """One candidate resolution for one UAS: a new plan (or none for a pure command), its
    cost (extra distance/time, normalised) and riskiness (normalised)."""

    operation_id: OperationId
    maneuver: Maneuver
    plan: FlightPlan | None
    cost: float
    risk: float
    detail: str = ""
    # What the option changes, for the pilot prompt (None: not computed for this option).
    extra_length_m: float | None = None
    """3D path length this option adds to the remaining plan."""
    extra_time_s: float | None = None
    """Time this option adds to the arrival at the plan's last waypoint."""
    separation_ratio: float | None = None
    """Closest predicted separation from the other plans under this option, as a multiple
    of the separation minima (at least 1: separated; cylinder rule: the larger of horizontal
    distance / horizontal minimum and vertical distance / vertical minimum). None: no other
    plan in range."""
    fence_distance_m: float | None = None
    """Closest horizontal distance to an active geofence (negative: inside). None: none near."""
    offset_m: float | None = None
    """How far (3D) the new path goes from the current one at most: the manoeuvre's size."""
    closest: Closest | None = None
    """Where :attr:`separation_ratio` is reached, in metres (None: not known)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Closest:
    """The closest predicted separation of an option from another plan, in metres, and the
    minima the ratio was taken against (the pair's effective minima: what a loss is)."""

    other: str
    """The other UAS ("" when not known)."""
    horizontal_m: float
    vertical_m: float
    min_horizontal_m: float
    min_vertical_m: float
    spherical: bool = False
    """Sphere mode: the separation is the 3D distance, the minimum ``min_horizontal_m``."""


class CommandKind(Enum):
    HOLD = "hold"
    RESUME = "resume"
    LAND = "land"
    RTL = "rtl"
    GOTO = "goto"


@dataclass(frozen=True, slots=True, kw_only=True)
class Command:
    kind: CommandKind
    operation_id: OperationId
    target: Position | None = None


class RecommendationState(Enum):
    PROPOSED = "proposed"
    ACCEPTED = "accepted"
    REJECTED = "rejected"
    EXPIRED = "expired"
    UPLOADING = "uploading"
    APPLIED = "applied"
    FAILED = "failed"
    SUPERSEDED = "superseded"


# Allowed lifecycle transitions (proposed -> accepted|rejected|expired -> uploading ->
# applied|failed). SUPERSEDED closes a proposal that EM replaced before it was answered.
RECOMMENDATION_TRANSITIONS: dict[RecommendationState, frozenset[RecommendationState]] = {
    RecommendationState.PROPOSED: frozenset(
        {
            RecommendationState.ACCEPTED,
            RecommendationState.REJECTED,
            RecommendationState.EXPIRED,
            RecommendationState.SUPERSEDED,
        }
    ),
    RecommendationState.ACCEPTED: frozenset(
        {RecommendationState.UPLOADING, RecommendationState.APPLIED, RecommendationState.FAILED}
    ),
    RecommendationState.UPLOADING: frozenset(
        {RecommendationState.APPLIED, RecommendationState.FAILED}
    ),
    RecommendationState.REJECTED: frozenset(),
    RecommendationState.EXPIRED: frozenset(),
    RecommendationState.APPLIED: frozenset(),
    RecommendationState.FAILED: frozenset(),
    RecommendationState.SUPERSEDED: frozenset(),
}


class TransitionError(ValueError):
    def __init__(
        self, rec_id: RecommendationId, old: RecommendationState, new: RecommendationState
    ) -> None:
        super().__init__(f"recommendation {rec_id}: cannot go from {old.value} to {new.value}")
        self.rec_id = rec_id
        self.old = old
        self.new = new


@dataclass(frozen=True, slots=True, kw_only=True)
class Recommendation:
    """What EM proposes to the pilot of one UAS for one threat.

    ``selected`` is the chosen alternative (its plan is what gets uploaded on accept), or a
    ``command``; ``alternatives`` are the others the pilot may view. ``version`` increases when
    EM re-plans for the same threat and UAS; answers must name id and version.
    """

    id: RecommendationId
    version: int
    threat_id: ThreatId
    threat_kind: ThreatKind
    operation_id: OperationId
    created_t_s: float
    deadline_t_s: float
    selected: Alternative | None = None
    command: Command | None = None
    alternatives: tuple[Alternative, ...] = ()
    state: RecommendationState = RecommendationState.PROPOSED
    reason: str = ""
    new_geofence: Geofence | None = None
    state_t_s: float | None = None

    def transition(self, new: RecommendationState, t_s: float, reason: str = "") -> Recommendation:
        """Return a copy in state ``new`` or raise :class:`TransitionError`."""
        if new not in RECOMMENDATION_TRANSITIONS[self.state]:
            raise TransitionError(self.id, self.state, new)
        from dataclasses import replace

        return replace(self, state=new, state_t_s=t_s, reason=reason or self.reason)


@dataclass(frozen=True, slots=True, kw_only=True)
class AuditEntry:
    """One automated decision or operator answer, for the store's audit log."""

    t_s: float
    actor: str
    action: str
    subject: str
    detail: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class AirspaceSnapshot:
    """One consistent view of the airspace at ``t_s``: what Monitoring checks and what EM/TD
    decide on. ``tracks`` and ``operations`` are keyed by id; ``prediction`` covers the tracks
    (cooperative and intruders) at the same ``t_s``."""

    t_s: float
    operations: dict[OperationId, Operation]
    tracks: Mapping[TrackId, Track]
    geofences: tuple[Geofence, ...]
    prediction: PredictedTrajectories | None = None
    airborne: frozenset[OperationId] = frozenset()
    """Operations whose vehicle is in the air by its own messages (armed and not landed: see
    docs/autopilots.md, "Vehicle state"): traffic from take-off to landing, whatever their plan
    says. Operations whose vehicle reports nothing (ADS-B only, a scenario) are in neither
    set."""
    grounded: frozenset[OperationId] = frozenset()
    """Operations whose vehicle is on the ground (disarmed, or armed and landed): nothing is
    decided for them but pre-flight checks."""
    grounded_tracks: frozenset[TrackId] = frozenset()
    """Tracks of MAVLink vehicles without an operation that are on the ground by their own
    messages: not intruders (services/ground_vehicles.py)."""
