"""Messages that cross the U-space Service Manager: what adapters produce from the wire and what
the services hand back to the world. Plain frozen dataclasses with units in names.

Position measurements themselves are :class:`gcs_utm.model.Measurement`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from gcs_utm.model import (
    Autopilot,
    Geofence,
    Icao24,
    OperationId,
    Position,
    RecommendationId,
    SysId,
    ThreatKind,
    VehicleKind,
)


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleKey:
    """A vehicle on a link. System ids are 8-bit, so the link and source address are part of
    the identity: more than 255 vehicles can share one endpoint."""

    link: str
    address: str
    sys_id: SysId
    comp_id: int = 1


class FlightMode(Enum):
    """Autopilot-independent flight mode (PX4 custom modes and ArduPilot modes map here)."""

    UNKNOWN = "unknown"
    MANUAL = "manual"
    TAKEOFF = "takeoff"
    MISSION = "mission"
    HOLD = "hold"
    RTL = "rtl"
    LAND = "land"
    GUIDED = "guided"
    OFFBOARD = "offboard"


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleStatus:
    """Latest non-position state of a vehicle (HEARTBEAT, SYS_STATUS, GPS_RAW_INT, ...)."""

    sys_id: SysId
    t_s: float
    link: str = ""
    autopilot: Autopilot = Autopilot.UNKNOWN
    vehicle_kind: VehicleKind | None = None
    mode: FlightMode = FlightMode.UNKNOWN
    armed: bool = False
    landed: bool | None = None
    battery_pct: float | None = None
    battery_v: float | None = None
    gnss_fix_type: int | None = None
    gnss_satellites: int | None = None
    eph_m: float | None = None
    epv_m: float | None = None
    mission_seq: int | None = None
    mission_total: int | None = None
    vehicle: str = ""  # where it was first heard (as LinkHealth.vehicle)
    home: Position | None = None  # HOME_POSITION (AMSL), None until the vehicle sets one
    mission_id: int | None = None  # MISSION_CURRENT's opaque mission id, when it sends one
    position: Position | None = None  # the last reported position (GLOBAL_POSITION_INT)
    position_t_s: float | None = None  # when the vehicle took it (capture time, service clock)
    reboots: int = 0  # reboots seen (time_boot_ms going back): each starts a new pre-flight
    heading_deg: float | None = None  # GLOBAL_POSITION_INT hdg (yaw, true north), if sent


@dataclass(frozen=True, slots=True, kw_only=True)
class LinkHealth:
    """Per-vehicle link statistics. ``vehicle`` is the ``host:port`` the vehicle was first
    heard from (as :attr:`gcs_utm.model.Measurement.vehicle`): vehicles sharing a system id
    on one link have a health each."""

    sys_id: SysId
    link: str
    last_heard_t_s: float
    rate_hz: float
    received: int
    lost: int
    bad_frames: int
    reboots: int
    vehicle: str = ""
    clock_jumps: int = 0  # re-anchors of the vehicle clock mapping (docs/vehicle-time.md)
    system_time_rejected: int = 0  # SYSTEM_TIME that disagreed with arrival times


@dataclass(frozen=True, slots=True, kw_only=True)
class HazardReport:
    """A threat the USM raises from outside Monitoring: jamming signs, low battery, link loss,
    technical failure, a stakeholder alert (wildfire, weather) with an area."""

    kind: ThreatKind
    t_s: float
    operation_id: OperationId | None = None
    sys_id: SysId | None = None
    icao24: Icao24 | None = None
    position: Position | None = None
    area: Geofence | None = None
    message: str = ""
    source: str = ""


class PilotDecision(Enum):
    ACCEPT = "accept"
    REJECT = "reject"


@dataclass(frozen=True, slots=True, kw_only=True)
class PilotAnswer:
    """An operator's answer to one exact recommendation version (dashboard or MQTT)."""

    recommendation_id: RecommendationId
    version: int
    decision: PilotDecision
    t_s: float
    operator: str = "default"
    source: str = "dashboard"
    alternative_index: int | None = None
