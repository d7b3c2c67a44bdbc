"""Remote ID reported over MAVLink -> identity, positions and consistency threats.

Each OPEN_DRONE_ID_BASIC_ID / LOCATION / SYSTEM / OPERATOR_ID / SELF_ID (and each message of
an OPEN_DRONE_ID_MESSAGE_PACK, decoded by :mod:`adapters.remoteid.f3411`) updates the record of
the aircraft it is about:

- ``id_or_mac`` zero: the sending vehicle itself (record ``sysid:<n>``). Its Remote ID
  Location is compared with its telemetry position (GLOBAL_POSITION_INT no older than
  ``_FIX_MAX_AGE_S``): farther than ``consistency_m`` plus the message's own horizontal
  accuracy bound raises a REMOTE_ID_MISMATCH hazard (a spoofed or broken Remote ID). A vehicle
  with no telemetry position gets the Remote ID location as its position (a measurement with
  its system id: its operation's track, else ``sysid:<n>``).
- ``id_or_mac`` set: another aircraft the vehicle's receiver heard (record ``rid:<hex>``); its
  locations become measurements of the non-cooperative track ``rid:<hex>``.

A Basic ID that changes while the aircraft is airborne raises REMOTE_ID_MISMATCH too. Identity
changes are reported through ``on_identity`` with the record and a line of text (the USM
event log, and the store's audit log as :func:`identity_audit`); :attr:`RidIngest.aircraft`
holds the latest of each record.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

from adapters.mavlink import wire
from adapters.mavlink.transfer import MavlinkError
from adapters.mavlink.vehicle import Events, VehicleState
from adapters.remoteid import f3411
from adapters.remoteid.f3411 import IdType, OperationalStatus, UaType
from adapters.remoteid.vehicles import (
    ODID_BASIC_ID,
    ODID_LOCATION,
    ODID_MESSAGE_PACK,
    ODID_OPERATOR_ID,
    ODID_SELF_ID,
    ODID_SYSTEM,
    RidVehicles,
)
from gcs_utm.geo import haversine_m
from gcs_utm.messages import HazardReport
from gcs_utm.model import AuditEntry, Measurement, MeasurementSource, Position, SysId, ThreatKind

_FIX_MAX_AGE_S = 3.0  # a telemetry position older than this is not compared
_MAX_AIRCRAFT = 4096  # records kept; anybody in radio range can add one
_HACC_M = (None, 18520.0, 7408.0, 3704.0, 1852.0, 926.0, 555.6, 185.2, 92.6, 30.0, 10.0, 3.0, 1.0)
_VACC_M = (None, 150.0, 45.0, 25.0, 10.0, 3.0, 1.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class RidAircraft:
    """What Remote ID says about one aircraft."""

    key: str  # "sysid:<n>" (the sending vehicle) or "rid:<id_or_mac hex>"
    sys_id: int | None  # the vehicle it is about; None for an aircraft a receiver heard
    uas_id: str = ""
    id_type: IdType | None = None
    ua_type: UaType | None = None
    operator_id: str = ""
    self_id: str = ""
    status: OperationalStatus | None = None
    position: Position | None = None
    horizontal_accuracy_m: float | None = None
    position_t_s: float | None = None
    operator_position: Position | None = None
    updated_t_s: float = 0.0


@dataclass(slots=True)
class RidIngestCounters:
    locations: int = 0  # Remote ID locations read
    measurements: int = 0  # of them, handed to tracking as positions
    checked: int = 0  # compared with the vehicle's telemetry position
    mismatches: int = 0  # REMOTE_ID_MISMATCH hazards raised (location or identity)
    packs: int = 0  # message packs decoded
    bad: int = 0  # messages or packs that could not be decoded


@dataclass(frozen=True, slots=True, kw_only=True)
class _Loc:
    lat_deg: float
    lon_deg: float
    alt_m: float | None
    hacc_m: float | None
    vacc_m: float | None
    status: OperationalStatus | None


class RidIngest:
    """See the module docstring. :meth:`register` adds its readers to the hub's handlers."""

    def __init__(
        self,
        *,
        consistency_m: float,
        position_of: Callable[[int], tuple[Position, float] | None],
        on_identity: Callable[[RidAircraft, str], None] = lambda _rec, _text: None,
    ) -> None:
        self.consistency_m = consistency_m
        self.counters = RidIngestCounters()
        self.aircraft: dict[str, RidAircraft] = {}
        self._position_of = position_of  # sysid -> (telemetry position, its receipt time)
        self._on_identity = on_identity

    def register(self, vehicles: RidVehicles) -> None:
        vehicles.add_reader(ODID_BASIC_ID, self.on_basic_id)
        vehicles.add_reader(ODID_LOCATION, self.on_location)
        vehicles.add_reader(ODID_SYSTEM, self.on_system)
        vehicles.add_reader(ODID_OPERATOR_ID, self.on_operator_id)
        vehicles.add_reader(ODID_SELF_ID, self.on_self_id)
        vehicles.add_reader(ODID_MESSAGE_PACK, self.on_message_pack)

    # --- MAVLink readers (VehicleState, message, receipt time, events, about another UA) ----
    def on_basic_id(
        self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events, other: bool
    ) -> None:
        uas_id = bytes(m.uas_id).split(b"\0", 1)[0].decode("ascii", "replace")
        key = self._key(st, m, other)
        self._basic_id(
            st, key, t_s, ev, uas_id=uas_id, id_type=int(m.id_type), ua_type=int(m.ua_type)
        )

    def on_location(
        self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events, other: bool
    ) -> None:
        if m.latitude == 0 and m.longitude == 0:
            return  # no position yet
        alt = float(m.altitude_geodetic)
        loc = _Loc(
            lat_deg=m.latitude / 1e7,
            lon_deg=m.longitude / 1e7,
            alt_m=None if alt <= -1000.0 else alt,
            hacc_m=_table(_HACC_M, int(m.horizontal_accuracy)),
            vacc_m=_table(_VACC_M, int(m.vertical_accuracy)),
            status=_status(int(m.status)),
        )
        self._location(st, self._key(st, m, other), loc, t_s, ev)

    def on_system(
        self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events, other: bool
    ) -> None:
        if m.operator_latitude == 0 and m.operator_longitude == 0:
            return
        alt = float(m.operator_altitude_geo)
        where = Position(
            lat_deg=m.operator_latitude / 1e7,
            lon_deg=m.operator_longitude / 1e7,
            alt_amsl_m=0.0 if alt <= -1000.0 else alt,
        )
        self._update(st, self._key(st, m, other), t_s, operator_position=where)

    def on_operator_id(
        self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events, other: bool
    ) -> None:
        text = str(m.operator_id).rstrip("\x00")
        self._identity(st, self._key(st, m, other), t_s, operator_id=text)

    def on_self_id(
        self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events, other: bool
    ) -> None:
        self._update(st, self._key(st, m, other), t_s, self_id=str(m.description).rstrip("\x00"))

    def on_message_pack(
        self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events, other: bool
    ) -> None:
        """The F3411 messages of a pack, decoded by our broadcast decoder."""
        size, count = int(m.single_message_size), int(m.msg_pack_size)
        raw = bytes([0xF2, size, count]) + bytes(m.messages)[: size * count]
        try:
            msgs = f3411.decode_pack(raw)
        except f3411.RemoteIdError:
            self.counters.bad += 1
            return
        self.counters.packs += 1
        key = self._key(st, m, other)
        for msg in msgs:
            self._apply(st, key, msg, t_s, ev)

    # --- shared ---------------------------------------------------------------------------
    def _apply(
        self, st: VehicleState, key: str, msg: f3411.Message, t_s: float, ev: Events
    ) -> None:
        if isinstance(msg, f3411.BasicId):
            self._basic_id(
                st,
                key,
                t_s,
                ev,
                uas_id=msg.uas_id,
                id_type=msg.id_type.value,
                ua_type=msg.ua_type.value,
            )
        elif isinstance(msg, f3411.Location):
            if msg.latitude_deg is not None and msg.longitude_deg is not None:
                loc = _Loc(
                    lat_deg=msg.latitude_deg,
                    lon_deg=msg.longitude_deg,
                    alt_m=msg.altitude_geodetic_m,
                    hacc_m=msg.horizontal_accuracy_m,
                    vacc_m=msg.vertical_accuracy_m,
                    status=msg.status,
                )
                self._location(st, key, loc, t_s, ev)
        elif isinstance(msg, f3411.OperatorId):
            self._identity(st, key, t_s, operator_id=msg.operator_id)
        elif isinstance(msg, f3411.SelfId):
            self._update(st, key, t_s, self_id=msg.description)
        elif isinstance(msg, f3411.System) and msg.operator_latitude_deg is not None:
            where = Position(
                lat_deg=msg.operator_latitude_deg,
                lon_deg=msg.operator_longitude_deg or 0.0,
                alt_amsl_m=msg.operator_altitude_geodetic_m or 0.0,
            )
            self._update(st, key, t_s, operator_position=where)

    @staticmethod
    def _key(st: VehicleState, m: wire.MavMsg, other: bool) -> str:
        if not other:
            return f"sysid:{st.sys_id}"
        return "rid:" + bytes(m.id_or_mac).rstrip(b"\0").hex()

    def _record(self, st: VehicleState, key: str) -> RidAircraft:
        rec = self.aircraft.get(key)
        if rec is None:
            if len(self.aircraft) >= _MAX_AIRCRAFT:  # forget the least recently updated
                oldest = min(self.aircraft.values(), key=lambda r: r.updated_t_s)
                del self.aircraft[oldest.key]
            rec = RidAircraft(key=key, sys_id=st.sys_id if key.startswith("sysid:") else None)
        return rec

    def _update(self, st: VehicleState, key: str, t_s: float, **changes: object) -> RidAircraft:
        rec = replace(self._record(st, key), updated_t_s=t_s, **changes)  # type: ignore[arg-type]
        self.aircraft[key] = rec
        return rec

    def _identity(self, st: VehicleState, key: str, t_s: float, **changes: object) -> None:
        before = self.aircraft.get(key)
        rec = self._update(st, key, t_s, **changes)
        if before is None or any(getattr(before, k) != v for k, v in changes.items()):
            self._on_identity(
                rec,
                f"{key}: Remote ID "
                + ", ".join(f"{k.replace('_', ' ')} {v!s}" for k, v in changes.items())
                + (f" (serial {rec.uas_id})" if "uas_id" not in changes and rec.uas_id else ""),
            )

    def _basic_id(
        self,
        st: VehicleState,
        key: str,
        t_s: float,
        ev: Events,
        *,
        uas_id: str,
        id_type: int,
        ua_type: int,
    ) -> None:
        before = self.aircraft.get(key)
        kind = IdType(id_type) if id_type in IdType._value2member_map_ else None
        if (
            before is not None
            and before.uas_id
            and before.id_type is kind
            and before.uas_id != uas_id
            and before.status is OperationalStatus.AIRBORNE
        ):
            self._mismatch(
                st,
                key,
                t_s,
                ev,
                f"Remote ID identity changed in flight: {before.uas_id} -> {uas_id}",
            )
        ua = UaType(ua_type) if 0 <= ua_type <= 15 else None
        self._identity(st, key, t_s, uas_id=uas_id, id_type=kind, ua_type=ua)

    def _location(self, st: VehicleState, key: str, loc: _Loc, t_s: float, ev: Events) -> None:
        c = self.counters
        c.locations += 1
        alt = loc.alt_m
        where = Position(
            lat_deg=loc.lat_deg, lon_deg=loc.lon_deg, alt_amsl_m=0.0 if alt is None else alt
        )
        self._update(
            st, key, t_s, position=where, horizontal_accuracy_m=loc.hacc_m, position_t_s=t_s,
            status=loc.status,
        )  # fmt: skip
        own = key.startswith("sysid:")
        fix = self._position_of(st.sys_id) if own else None
        if fix is not None and t_s - fix[1] <= _FIX_MAX_AGE_S:
            c.checked += 1
            tel = fix[0]
            d_m = haversine_m(tel.lat_deg, tel.lon_deg, loc.lat_deg, loc.lon_deg)
            allowed_m = self.consistency_m + (loc.hacc_m or 0.0)
            if d_m > allowed_m:
                self._mismatch(
                    st, key, t_s, ev,
                    f"Remote ID location {d_m:.0f} m from the telemetry position "
                    f"(allowed {allowed_m:.0f} m): spoofed or faulty Remote ID",
                )  # fmt: skip
            return
        if alt is None:
            return  # a track needs an altitude
        c.measurements += 1
        ev.on_measurement(
            Measurement(
                source=MeasurementSource.TELEMETRY,
                capture_t_s=t_s,
                receipt_t_s=t_s,
                lat_deg=loc.lat_deg,
                lon_deg=loc.lon_deg,
                alt_amsl_m=alt,
                eph_m=None if loc.hacc_m is None else loc.hacc_m / 2.0,  # 95 % -> ~1 sigma
                epv_m=None if loc.vacc_m is None else loc.vacc_m / 2.0,
                sys_id=SysId(st.sys_id) if own else None,
                link=f"{st.key.link}:remote-id:{st.sys_id}",
                vehicle="" if own else key,
            )
        )

    def _mismatch(self, st: VehicleState, key: str, t_s: float, ev: Events, text: str) -> None:
        self.counters.mismatches += 1
        ev.on_hazard(
            HazardReport(
                kind=ThreatKind.REMOTE_ID_MISMATCH,
                t_s=t_s,
                sys_id=SysId(st.sys_id) if key.startswith("sysid:") else None,
                position=self.aircraft[key].position if key in self.aircraft else None,
                message=f"{key}: {text}",
                source=f"remote-id:{st.key.link}",
            )
        )


def _table(table: tuple[float | None, ...], code: int) -> float | None:
    return table[code] if 0 <= code < len(table) else None


def _status(code: int) -> OperationalStatus | None:
    return OperationalStatus(code) if code in OperationalStatus._value2member_map_ else None


def identity_audit(rec: RidAircraft) -> AuditEntry:
    """The store's audit entry for an identity a Remote ID record now holds."""
    return AuditEntry(
        t_s=rec.updated_t_s,
        actor="remote-id",
        action="identity",
        subject=rec.key,
        detail={
            "sys_id": rec.sys_id,
            "uas_id": rec.uas_id,
            "id_type": None if rec.id_type is None else rec.id_type.name,
            "ua_type": None if rec.ua_type is None else rec.ua_type.name,
            "operator_id": rec.operator_id,
        },
    )


class _States(Protocol):
    def state(self, vehicle: SysId) -> VehicleState: ...


def telemetry_positions(hub: _States) -> Callable[[int], tuple[Position, float] | None]:
    """``position_of`` for :class:`RidIngest` from the hub: a vehicle's last GLOBAL_POSITION_INT
    position and when the vehicle was last heard (its telemetry streams continuously)."""

    def position_of(sys_id: int) -> tuple[Position, float] | None:
        try:
            st = hub.state(SysId(sys_id))
        except MavlinkError:
            return None
        where = st.last_position
        return None if where is None else (where, st.last_heard_t_s)

    return position_of
