"""What a loaded scenario is: the airspace frame, the filed operations, geofences, scripted
events and the simulated vehicles to start.

Invariants: every time here is absolute POSIX seconds (``t0_s`` + the file's relative time),
except :attr:`ScenarioEvent.at_s` and :attr:`VehicleSetup.start_delay_s`, which keep the
file's relative seconds for readability in logs; positions are WGS84 degrees and metres AMSL.
A :class:`Scenario` is only ever returned complete: loaders raise :class:`ScenarioError`
before building anything half-valid.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any, TypeVar

from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    Geofence,
    Icao24,
    Operation,
    OperationId,
    Position,
    SysId,
    VehicleKind,
)

_Config = TypeVar("_Config", bound=Any)


class ScenarioError(ValueError):
    """A bad scenario file: ``file``, the ``item`` (e.g. ``operations[1] (UAS2)``), the
    ``field`` (e.g. ``waypoints[3].t_s``) and what is wrong."""

    def __init__(self, file: str, item: str, field: str, message: str) -> None:
        where = item if field == item else f"{item}: {field}"
        super().__init__(f"{file}: {where}: {message}")
        self.file = file
        self.item = item
        self.field = field
        self.message = message


class EventKind(Enum):
    """Scripted faults and alerts a scenario injects (the paper's threat sources)."""

    GNSS_JAMMING = "gnss_jamming"
    SPOOFING = "spoofing"
    BATTERY_DROP = "battery_drop"
    BATTERY_DRAIN = "battery_drain"
    LINK_LOSS = "link_loss"
    PACKET_LOSS = "packet_loss"
    MOTOR_FAILURE = "motor_failure"
    ALERT_AREA = "alert_area"


@dataclass(frozen=True, slots=True, kw_only=True)
class ScenarioEvent:
    """One scripted event at ``t_s`` (= t0 + ``at_s``).

    ``uas`` is the operation it hits (``None`` for an alert area not tied to one UAS).
    ``value`` is kind-specific: jamming/spoofing strength 0..1, battery drop in percent,
    battery drain in percent per second, packet-loss ratio 0..1, spoofing offset in metres.
    ``area`` is the no-fly volume an ``alert_area`` asks to create (a dynamic geofence).
    """

    at_s: float
    t_s: float
    kind: EventKind
    uas: OperationId | None = None
    duration_s: float | None = None
    value: float | None = None
    area: Geofence | None = None
    reason: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleSetup:
    """Everything needed to start one simulated vehicle for an operation.

    ``start_delay_s``: the vehicle starts its mission this many seconds after the filed plan
    says (a late start is how use case 1 creates its loss of separation).
    """

    operation_id: OperationId
    sys_id: SysId | None
    icao24: Icao24 | None
    autopilot: Autopilot
    vehicle_kind: VehicleKind
    home: Position
    plan: FlightPlan
    cruise_speed_mps: float
    max_climb_rate_mps: float
    start_delay_s: float = 0.0
    endurance_s: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """A complete, validated scenario. ``t0_s`` is the absolute time of relative second 0."""

    name: str
    description: str
    duration_s: float
    t0_s: float
    frame: LocalFrame
    operations: tuple[Operation, ...]
    geofences: tuple[Geofence, ...]
    events: tuple[ScenarioEvent, ...]
    vehicles: tuple[VehicleSetup, ...]
    source: str = ""
    safety_distance_m: float | None = None
    """The scenario's own single 3D separation minimum (GAUSS ``safetyDistance``), or None
    for the settings' rule. When set, ``gcs-utm run`` and ``scenario check`` use
    ``separation_mode = "sphere"`` with it (:func:`monitoring_for`)."""

    _by_id: dict[str, tuple[Operation | None, VehicleSetup | None]] = field(
        init=False, repr=False, compare=False, default_factory=dict
    )
    """Operation and vehicle per operation id, built on first use: a lookup per operation
    must not scan them all (a 10,000-operation airspace)."""

    def _lookup(self, op_id: str) -> tuple[Operation | None, VehicleSetup | None]:
        index = self._by_id
        if not index and (self.operations or self.vehicles):
            ops = {op.id: op for op in reversed(self.operations)}  # the first of an id wins
            setups = {v.operation_id: v for v in reversed(self.vehicles)}
            for key in ops.keys() | setups.keys():
                index[key] = (ops.get(key), setups.get(key))
        return index.get(op_id, (None, None))

    def operation(self, op_id: str) -> Operation:
        """The operation with id ``op_id`` (KeyError if none)."""
        op = self._lookup(op_id)[0]
        if op is None:
            raise KeyError(op_id)
        return op

    def monitoring_for(self, config: _Config) -> _Config:
        """A ``MonitoringConfig`` with this scenario's separation rule applied (unchanged
        without one). Typed loosely: this layer sits below ``gcs_utm.core``."""
        if self.safety_distance_m is None:
            return config
        return replace(config, separation_mode="sphere", safety_distance_m=self.safety_distance_m)

    def vehicle(self, op_id: str) -> VehicleSetup:
        """The vehicle of operation ``op_id`` (KeyError if none)."""
        setup = self._lookup(op_id)[1]
        if setup is None:
            raise KeyError(op_id)
        return setup
