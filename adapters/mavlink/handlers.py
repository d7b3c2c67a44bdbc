"""The one table of per-message telemetry handlers: MAVLink message id -> what a vehicle's
:class:`~adapters.mavlink.vehicle.VehicleState` does with it.

The hub (:class:`adapters.mavlink.hub.MavlinkHub`) dispatches through
:func:`message_handlers`, for live links and for replayed recordings alike (``gcs-utm replay``
feeds them to a replay link of the hub: :mod:`gcs_utm.app.replay`), HOME_POSITION included:
the vehicle's home, against which relative altitudes are read.
Messages outside the table are not telemetry (mission and command protocol messages go to the
hub's transfer mailboxes) or not used.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from adapters.mavlink import wire
from adapters.mavlink.adsb_relay import AdsbRelay, MessageHandler
from adapters.mavlink.vehicle import VehicleState
from adapters.remoteid.vehicles import RidVehicles

VEHICLE_HANDLERS: Mapping[int, MessageHandler] = MappingProxyType(
    {
        wire.HEARTBEAT: VehicleState.on_heartbeat,
        wire.GLOBAL_POSITION_INT: VehicleState.on_global_position,
        wire.GPS_RAW_INT: VehicleState.on_gps_raw,
        wire.SYS_STATUS: VehicleState.on_sys_status,
        wire.BATTERY_STATUS: VehicleState.on_battery_status,
        wire.MISSION_CURRENT: VehicleState.on_mission_current,
        wire.EXTENDED_SYS_STATE: VehicleState.on_extended_sys_state,
        wire.STATUSTEXT: VehicleState.on_statustext,
        wire.SYSTEM_TIME: VehicleState.on_system_time,
        wire.HOME_POSITION: VehicleState.on_home_position,
    }
)
"""The handlers that need nothing but the vehicle's state (read-only)."""


def message_handlers(
    adsb_relay: AdsbRelay, remote_id: RidVehicles | None = None
) -> dict[int, MessageHandler]:
    """The full table: :data:`VEHICLE_HANDLERS` plus ``ADSB_VEHICLE`` relayed to
    ``adsb_relay`` (which keeps its own counters, one per hub or replay), and the
    OPEN_DRONE_ID_* messages and ArduPilot's ODID texts to ``remote_id`` (docs/remote-id.md)."""
    table = dict(VEHICLE_HANDLERS)
    table[wire.ADSB_VEHICLE] = adsb_relay.on_adsb_vehicle
    if remote_id is not None:
        table.update(remote_id.handlers(table.get(wire.STATUSTEXT)))
    return table
