"""The operator's side of Remote ID, sent to every vehicle that carries it.

A Remote ID transmitter broadcasts what the UA knows (Location, from the autopilot) and what
only the ground side knows: the operator's location (System), the operator's registration
(Operator ID) and, where the vehicle has none stored, the UA's serial number (Basic ID). A GCS
supplies them over MAVLink as MAVProxy's ``opendroneid`` module does: OPEN_DRONE_ID_SYSTEM at
``system_period_s`` (ArduPilot refuses to arm when none came for 3 s, and says "ODID: lost
operator location"), OPEN_DRONE_ID_BASIC_ID and OPEN_DRONE_ID_OPERATOR_ID at
``static_period_s``.

Per vehicle, from its operation (the one filed for its system id: active first, then
suspended, then planned) and ``[remote_id]``:
- operator location: ``operator_locations[operator]`` (type FIXED), else the operation's home,
  else its first waypoint (type TAKEOFF); without an operation ``operator_locations.default``;
- operator ID: ``operator_ids[operator]`` (``default`` without an operation);
- serial number: ``serial_numbers[sysid]``; UA type from the operation's (else the vehicle's)
  kind; classification: ``classifications[sysid]`` else ``default_classification``.

A declared vehicle with no operation filed for its system id is a REMOTE_ID_MISMATCH hazard
(``on_hazard``, once per vehicle until it has one): it broadcasts an identity nobody filed.
What is missing is reported once per vehicle and cause through ``on_problem`` (the USM's
event log): no operator location means nothing is sent and an ArduPilot enforcing Remote ID
does not arm. Pure apart from the hub it sends through; :meth:`tick` does one round.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

from adapters.mavlink.transfer import MavlinkError, TransferError
from adapters.mavlink.vehicle import VehicleInfo
from adapters.remoteid.config import OperatorLocation, RemoteIdConfig, parse_operator_location
from adapters.remoteid.f3411 import (
    ODID_EPOCH_UTC_S,
    ClassificationType,
    IdType,
    OperatorLocationType,
    UaType,
)
from adapters.remoteid.identity import Classification, parse_classification
from adapters.remoteid.vehicles import DeclaredVehicle, RidVehicles
from gcs_utm.clock import Clock
from gcs_utm.messages import HazardReport
from gcs_utm.model import Operation, OperationState, SysId, ThreatKind, VehicleKind

_log = logging.getLogger(__name__)

_STATE_ORDER = (OperationState.ACTIVE, OperationState.SUSPENDED, OperationState.PLANNED)
_UA_TYPES = {
    VehicleKind.MULTIROTOR: UaType.HELICOPTER_OR_MULTIROTOR,
    VehicleKind.FIXED_WING: UaType.AEROPLANE,
}
_NO_MAC = [0] * 20  # id_or_mac: zero = about the vehicle itself, not a received UA
_ALT_UNKNOWN_M = -1000.0


class RidHub(Protocol):
    """What the operator side needs from the MAVLink hub."""

    def send_raw(self, vehicle: SysId, name: str, *args: Any) -> None: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class OperatorPart:
    """What gcs-utm tells one vehicle's Remote ID."""

    sys_id: int
    location: OperatorLocation | None  # None: no SYSTEM is sent (reported)
    location_type: OperatorLocationType
    classification: Classification
    operator_id: str | None
    serial_number: str | None
    ua_type: UaType


@dataclass(slots=True)
class RidOperatorCounters:
    system: int = 0  # OPEN_DRONE_ID_SYSTEM sent
    basic_id: int = 0
    operator_id: int = 0
    send_errors: int = 0  # the vehicle's link was down or the vehicle forgotten
    problems: int = 0  # distinct problems reported


@dataclass(slots=True)
class _Sent:
    static_t_s: float = float("-inf")
    problems: set[str] = field(default_factory=set)
    unfiled_reported: bool = False


class RemoteIdOperator:
    """See the module docstring."""

    def __init__(
        self,
        config: RemoteIdConfig,
        clock: Clock,
        hub: RidHub,
        *,
        vehicles: RidVehicles,
        known: Callable[[], Iterable[VehicleInfo]],
        operations: Callable[[], Iterable[Operation]],
        on_problem: Callable[[str], None],
        on_hazard: Callable[[HazardReport], None] = lambda _h: None,
    ) -> None:
        self.config = config
        self.clock = clock
        self.hub = hub
        self.counters = RidOperatorCounters()
        self.vehicles = vehicles
        self._known = known
        self._operations = operations
        self._on_problem = on_problem
        self._on_hazard = on_hazard
        self._sent: dict[int, _Sent] = {}
        self._locations = {
            k: parse_operator_location(v) for k, v in config.operator_locations.items()
        }

    async def run(self) -> None:
        if not self.config.enabled:
            return
        while True:
            self.tick(self.clock.now_s())
            await asyncio.sleep(self.config.system_period_s)

    def tick(self, t_s: float) -> None:
        """One round: SYSTEM to every declared vehicle, BASIC_ID and OPERATOR_ID to those
        whose last ones are ``static_period_s`` old."""
        self._preset(t_s)
        for sys_id, v in list(self.vehicles.declared.items()):
            sent = self._sent.setdefault(sys_id, _Sent())
            part = self.part_for(v, sent)
            static = t_s - sent.static_t_s >= self.config.static_period_s
            try:
                self._send(part, t_s, static=static)
            except (MavlinkError, TransferError, OSError) as exc:  # link down, vehicle forgotten
                self.counters.send_errors += 1
                _log.debug("remote id to sysid %d not sent: %s", sys_id, exc)
                continue
            if static:
                sent.static_t_s = t_s

    def _preset(self, t_s: float) -> None:
        """Vehicles listed in ``[remote_id] vehicles`` are declared once heard."""
        if not self.config.vehicles:
            return
        for info in self._known():
            sid = info.key.sys_id
            if sid in self.config.vehicles and sid not in self.vehicles.declared:
                self.vehicles.declared[sid] = DeclaredVehicle(
                    sys_id=sid,
                    autopilot=info.autopilot,
                    kind=info.vehicle_kind,
                    declared_t_s=t_s,
                    how="[remote_id] vehicles",
                )

    def operation_of(self, sys_id: int) -> Operation | None:
        ops = [op for op in self._operations() if op.sys_id == sys_id]
        for state in _STATE_ORDER:
            for op in ops:
                if op.state is state:
                    return op
        return None

    def part_for(self, v: DeclaredVehicle, sent: _Sent | None = None) -> OperatorPart:
        """The operator part for ``v``; what is missing is reported (once per cause)."""
        cfg = self.config
        op = self.operation_of(v.sys_id)
        if sent is not None:
            self._unfiled(v, sent, op is None)
        operator = op.operator if op is not None else "default"
        location, location_type = self._location(op, operator)
        if location is None:  # only without an operation: an operation has a take-off point
            self._problem(
                v,
                sent,
                f"no operator location for Remote ID vehicle sysid {v.sys_id}: no operation is "
                f"filed for it and [remote_id] operator_locations has no {operator!r}; it "
                "cannot arm if it enforces Remote ID",
            )
        operator_id = cfg.operator_ids.get(operator)
        if operator_id is None:
            self._problem(
                v,
                sent,
                f"no operator ID for operator {operator!r} ([remote_id] operator_ids): "
                f"sysid {v.sys_id} broadcasts none",
            )
        serial = cfg.serial_numbers.get(str(v.sys_id))
        if serial is None:
            self._problem(
                v,
                sent,
                f"no UA serial number for sysid {v.sys_id} ([remote_id] "
                "serial_numbers): its Basic ID is what the vehicle has stored, if anything",
            )
        kind = op.vehicle_kind if op is not None else v.kind
        text = cfg.classifications.get(str(v.sys_id), cfg.default_classification)
        return OperatorPart(
            sys_id=v.sys_id,
            location=location,
            location_type=location_type,
            classification=parse_classification(text),
            operator_id=operator_id,
            serial_number=serial,
            ua_type=_UA_TYPES.get(kind, UaType.NONE) if kind is not None else UaType.NONE,
        )

    def _unfiled(self, v: DeclaredVehicle, sent: _Sent, unfiled: bool) -> None:
        """A REMOTE_ID_MISMATCH hazard when ``v`` has no operation (once until it has one)."""
        if not unfiled:
            sent.unfiled_reported = False
            return
        if sent.unfiled_reported:
            return
        sent.unfiled_reported = True
        self._on_hazard(
            HazardReport(
                kind=ThreatKind.REMOTE_ID_MISMATCH,
                t_s=self.clock.now_s(),
                sys_id=SysId(v.sys_id),
                message=f"sysid {v.sys_id} declares Remote ID ({v.how}) but no operation is "
                "filed for it",
                source="remote-id",
            )
        )

    def _location(
        self, op: Operation | None, operator: str
    ) -> tuple[OperatorLocation | None, OperatorLocationType]:
        fixed = self._locations.get(operator)
        if fixed is not None:
            return fixed, OperatorLocationType.FIXED
        if op is None:
            return None, OperatorLocationType.TAKEOFF
        where = op.home if op.home is not None else op.plan.waypoints[0]
        return (
            OperatorLocation(
                latitude_deg=where.lat_deg,
                longitude_deg=where.lon_deg,
                altitude_amsl_m=where.alt_amsl_m,
            ),
            OperatorLocationType.TAKEOFF,
        )

    def _problem(self, v: DeclaredVehicle, sent: _Sent | None, text: str) -> None:
        if sent is None or text in sent.problems:
            return
        sent.problems.add(text)
        self.counters.problems += 1
        self._on_problem(text)

    def _send(self, part: OperatorPart, t_s: float, *, static: bool) -> None:
        loc = part.location
        eu = part.classification.category.value != 0 or part.classification.eu_class.value != 0
        if loc is not None:
            self._send_system(part, loc, t_s, eu=eu)
        if static:
            self._send_static(part)

    def _send_system(
        self, part: OperatorPart, loc: OperatorLocation, t_s: float, *, eu: bool
    ) -> None:
        self.hub.send_raw(
            SysId(part.sys_id),
            "open_drone_id_system",
            part.sys_id,
            0,  # every component: the autopilot and a transmitter
            _NO_MAC,
            part.location_type.value,
            (ClassificationType.EUROPEAN_UNION if eu else ClassificationType.UNDECLARED).value,
            round(loc.latitude_deg * 1e7),
            round(loc.longitude_deg * 1e7),
            1,  # area count: one UA
            0,  # area radius (m)
            _ALT_UNKNOWN_M,  # area ceiling
            _ALT_UNKNOWN_M,  # area floor
            part.classification.category.value,
            part.classification.eu_class.value,
            loc.altitude_amsl_m,  # geoid undulation not applied (docs/remote-id.md)
            max(0, int(t_s - ODID_EPOCH_UTC_S)),  # s since 2019-01-01 UTC
        )
        self.counters.system += 1

    def _send_static(self, part: OperatorPart) -> None:
        c = self.counters
        sid = SysId(part.sys_id)
        if part.serial_number is not None:
            uas_id = list(part.serial_number.encode("ascii").ljust(20, b"\0"))
            self.hub.send_raw(
                sid,
                "open_drone_id_basic_id",
                part.sys_id,
                0,
                _NO_MAC,
                IdType.SERIAL_NUMBER.value,
                part.ua_type.value,
                uas_id,
            )
            c.basic_id += 1
        if part.operator_id is not None:
            self.hub.send_raw(
                sid,
                "open_drone_id_operator_id",
                part.sys_id,
                0,
                _NO_MAC,
                0,  # MAV_ODID_OPERATOR_ID_TYPE_CAA
                part.operator_id.encode("ascii"),
            )
            c.operator_id += 1
