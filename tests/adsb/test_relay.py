"""ADSB_VEHICLE relayed by a vehicle (PX4/ArduPilot forward their ADS-B receiver's traffic):
pymavlink-encoded frames sent over UDP into the hub become ADS-B measurements."""

from __future__ import annotations

import asyncio
import socket
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mav

from adapters.adsb.mavlink import AdsbFlags
from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import RealClock
from gcs_utm.model import MeasurementSource
from tests.mavlink.conftest import Sink

pytestmark = [pytest.mark.network, pytest.mark.timeout(20)]

VALID = (
    AdsbFlags.VALID_COORDS
    | AdsbFlags.VALID_ALTITUDE
    | AdsbFlags.VALID_HEADING
    | AdsbFlags.VALID_VELOCITY
    | AdsbFlags.VALID_CALLSIGN
)


def adsb_vehicle(enc: Any, icao: int, lat_deg: float, lon_deg: float, **kw: Any) -> bytes:
    """One ADSB_VEHICLE frame: geometric altitude 600 m, 30 m/s north, 1 m/s climb."""
    msg = enc.adsb_vehicle_encode(
        icao,
        round(lat_deg * 1e7),
        round(lon_deg * 1e7),
        kw.get("altitude_type", 1),
        kw.get("altitude_mm", 600_000),
        kw.get("heading_cdeg", 0),
        kw.get("hor_velocity_cms", 3000),
        kw.get("ver_velocity_cms", 100),
        kw.get("callsign", b"INTR1"),
        1,  # ADSB_EMITTER_TYPE_LIGHT
        kw.get("tslc_s", 1),
        int(kw.get("flags", VALID)),
        1200,
    )
    return bytes(msg.pack(enc))


async def test_adsb_vehicle_on_a_link_becomes_an_adsb_measurement() -> None:
    sink = Sink()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), health_period_s=3600.0)
    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        port = hub.local_port("udpin:127.0.0.1:0")
        relay = mav.MAVLink(None, srcSystem=7, srcComponent=1)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            frames = [
                bytes(relay.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(relay)),
                adsb_vehicle(relay, 0xABC123, 47.40, 8.55),
                # no valid coordinates: dropped and counted
                adsb_vehicle(relay, 0xABC124, 47.40, 8.55, flags=AdsbFlags.VALID_ALTITUDE),
                # no valid velocity: a position without velocity
                adsb_vehicle(relay, 0xABC125, 47.41, 8.56, flags=VALID & ~AdsbFlags.VALID_VELOCITY),
            ]
            for f in frames:
                sock.sendto(f, ("127.0.0.1", port))
            loop = asyncio.get_running_loop()
            end = loop.time() + 5.0
            while hub.adsb_relay.counters.reports < 3:
                assert loop.time() < end, "the hub did not get the ADSB_VEHICLE frames"
                await asyncio.sleep(0.02)
        finally:
            sock.close()
    c = hub.adsb_relay.counters
    assert (c.reports, c.measurements, c.invalid) == (3, 2, 1)
    adsb = [m for m in sink.measurements if m.source is MeasurementSource.ADSB]
    assert [m.icao24 for m in adsb] == ["abc123", "abc125"]
    m = adsb[0]
    assert m.sys_id is None  # the relay is not the aircraft
    assert (m.lat_deg, m.lon_deg) == pytest.approx((47.40, 8.55))
    assert m.alt_amsl_m == pytest.approx(600.0)
    assert m.vel_ned_mps == pytest.approx((30.0, 0.0, -1.0), abs=1e-6)
    assert m.callsign == "INTR1"
    assert m.receipt_t_s - m.capture_t_s == pytest.approx(1.0)  # tslc
    assert "adsb-relay:7" in m.link
    assert adsb[1].vel_ned_mps is None
