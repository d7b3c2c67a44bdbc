"""``ADSB_VEHICLE`` relayed on a MAVLink link -> an ADS-B measurement.

PX4 (``ADSB_VEHICLE`` from its transponder driver) and ArduPilot (``ADSB`` library) forward the
traffic their ADS-B receiver hears. Each valid report becomes a :class:`Measurement` with
``source=ADSB`` and the aircraft's ICAO address (no system id: the sender is the relay, not
the aircraft), so Tracking associates it as any ADS-B report: an ICAO address bound to an
operation fuses with that operation's track, anything else is the intruder ``icao:<hex>``.
Field conversion and validity flags: :func:`adapters.adsb.adsb_vehicle_to_measurement`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from adapters.adsb import adsb_vehicle_to_measurement
from adapters.mavlink import wire
from adapters.mavlink.traffic_out import SYNTHETIC_ICAO_BASE
from adapters.mavlink.vehicle import Events, VehicleState

MessageHandler = Callable[[VehicleState, wire.MavMsg, float, Events], bool | None]
"""The hub's per-message handler: (vehicle state, message, receipt time, events)."""


@dataclass(slots=True)
class AdsbRelayCounters:
    reports: int = 0  # ADSB_VEHICLE frames handled
    measurements: int = 0  # of them, handed on as measurements
    invalid: int = 0  # no valid position/altitude flags, a bad ICAO address or coordinates
    echoes: int = 0  # our own traffic out coming back (a made-up address, traffic_out.py)


class AdsbRelay:
    """The hub's ``ADSB_VEHICLE`` handler (``handler(state, msg, t_s, events)``)."""

    def __init__(self) -> None:
        self.counters = AdsbRelayCounters()

    def on_adsb_vehicle(self, st: VehicleState, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        c = self.counters
        c.reports += 1
        if int(m.ICAO_address) >= SYNTHETIC_ICAO_BASE:
            c.echoes += 1
            return
        meas = adsb_vehicle_to_measurement(
            icao_address=int(m.ICAO_address),
            lat_e7=int(m.lat),
            lon_e7=int(m.lon),
            altitude_type=int(m.altitude_type),
            altitude_mm=int(m.altitude),
            heading_cdeg=int(m.heading),
            hor_velocity_cms=int(m.hor_velocity),
            ver_velocity_cms=int(m.ver_velocity),
            callsign=m.callsign,
            tslc_s=int(m.tslc),
            flags=int(m.flags),
            receipt_t_s=t_s,
            link=f"{st.key.link}:adsb-relay:{st.sys_id}",
        )
        if meas is None:
            c.invalid += 1
            return
        c.measurements += 1
        ev.on_measurement(meas)
