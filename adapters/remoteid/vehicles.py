"""Which vehicles carry Remote ID, from what they send (the hub's OPEN_DRONE_ID_* and
STATUSTEXT handlers), and what they report of their own Remote ID.

A vehicle declares Remote ID by sending any OPEN_DRONE_ID_* message (PX4 and ArduPilot with
``DID_MAVPORT`` on the GCS link send Location, Basic ID, System ... of their own; an ArduPilot
transmitter's ARM_STATUS is routed to the GCS link too) or one of ArduPilot's OpenDroneID
texts ("ODID: lost operator location" every 5 s while no operator location came, "ODID: lost
transmitter", "OpenDroneID: ..."), which it sends to every link with ``DID_ENABLE=1`` even when
its Remote ID messages go to another port. ``[remote_id] vehicles`` declares system ids
up front. A message whose ``id_or_mac`` is set describes another aircraft a vehicle's
receiver heard: it does not declare the sender.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from adapters.mavlink import wire
from adapters.mavlink.adsb_relay import MessageHandler
from adapters.mavlink.vehicle import Events, VehicleState
from gcs_utm.model import Autopilot, VehicleKind

ODID_BASIC_ID = 12900
ODID_LOCATION = 12901
ODID_AUTHENTICATION = 12902
ODID_SELF_ID = 12903
ODID_SYSTEM = 12904
ODID_OPERATOR_ID = 12905
ODID_MESSAGE_PACK = 12915
ODID_ARM_STATUS = 12918
ODID_SYSTEM_UPDATE = 12919
ODID_IDS = (
    ODID_BASIC_ID,
    ODID_LOCATION,
    ODID_AUTHENTICATION,
    ODID_SELF_ID,
    ODID_SYSTEM,
    ODID_OPERATOR_ID,
    ODID_MESSAGE_PACK,
    ODID_ARM_STATUS,
    ODID_SYSTEM_UPDATE,
)
_ODID_TEXTS = ("ODID:", "OpenDroneID:")  # ArduPilot AP_OpenDroneID's STATUSTEXT prefixes


@dataclass(slots=True)
class DeclaredVehicle:
    """A vehicle that carries Remote ID."""

    sys_id: int
    autopilot: Autopilot
    kind: VehicleKind | None
    declared_t_s: float
    how: str  # the message or text that declared it
    arm_status: int | None = None  # the transmitter's OPEN_DRONE_ID_ARM_STATUS (0 = good)
    arm_error: str = ""


@dataclass(slots=True)
class RidVehicleCounters:
    odid_messages: int = 0  # OPEN_DRONE_ID_* frames handled
    about_others: int = 0  # of them, with id_or_mac set: another aircraft heard
    declarations: int = 0  # vehicles that declared Remote ID


OdidReader = Callable[[VehicleState, wire.MavMsg, float, Events, bool], None]
"""Reads one OPEN_DRONE_ID_* message: (sender's state, message, receipt time, events, whether
it is about another aircraft (``id_or_mac`` set) rather than the sender)."""


class RidVehicles:
    """The hub's Remote ID handlers (see :meth:`handlers`) and the declared vehicles."""

    def __init__(self) -> None:
        self.counters = RidVehicleCounters()
        self.declared: dict[int, DeclaredVehicle] = {}
        self._readers: dict[int, OdidReader] = {}  # msg id -> what reads its content

    def add_reader(self, msg_id: int, reader: OdidReader) -> None:
        """Have ``reader`` read each ``msg_id`` message after the declaration (ingest)."""
        self._readers[msg_id] = reader

    def handlers(self, statustext: MessageHandler | None) -> dict[int, MessageHandler]:
        """Handlers to add to the hub's table: every OPEN_DRONE_ID_* message, and STATUSTEXT
        (``statustext``, the vehicle's own handler, runs first)."""
        table: dict[int, MessageHandler] = dict.fromkeys(ODID_IDS, self.on_odid)

        def on_statustext(st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events) -> None:
            if statustext is not None:
                statustext(st, m, t_s, ev)
            text = str(m.text).rstrip("\x00")
            if text.startswith(_ODID_TEXTS):
                self.declare(st, t_s, f"STATUSTEXT {text!r}")

        table[wire.STATUSTEXT] = on_statustext
        return table

    def on_odid(self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        self.counters.odid_messages += 1
        mid = wire.msg_id(m)
        about_other = any(getattr(m, "id_or_mac", ()) or ())
        if about_other:
            self.counters.about_others += 1
        v = self.declared.get(st.sys_id)
        if v is None and not about_other:
            v = self.declare(st, t_s, m.get_type())
        if mid == ODID_ARM_STATUS and v is not None:
            v.arm_status, v.arm_error = int(m.status), str(m.error).rstrip("\x00")
        reader = self._readers.get(mid)
        if reader is not None:
            reader(st, m, t_s, ev, about_other)

    def declare(self, st: VehicleState, t_s: float, how: str) -> DeclaredVehicle:
        v = self.declared.get(st.sys_id)
        if v is None:
            v = self.declared[st.sys_id] = DeclaredVehicle(
                sys_id=st.sys_id, autopilot=st.autopilot, kind=st.kind, declared_t_s=t_s, how=how
            )
            self.counters.declarations += 1
        elif v.kind is None:
            v.kind, v.autopilot = st.kind, st.autopilot
        return v
