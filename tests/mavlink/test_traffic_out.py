"""Traffic out (adapters/mavlink/traffic_out.py) through a real hub: each vehicle gets
ADSB_VEHICLE for the other aircraft near it, never its own track, nothing stale or far; the
made-up address of a UAS that comes back relayed by a vehicle is dropped, not an intruder."""

from __future__ import annotations

import asyncio
import os
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.traffic_out import (
    SYNTHETIC_ICAO_BASE,
    TrafficOut,
    TrafficOutConfig,
    icao_address,
)
from gcs_utm.clock import RealClock
from gcs_utm.model import (
    FlightPlan,
    Icao24,
    Operation,
    OperationId,
    SysId,
    Track,
    TrackId,
    VehicleKind,
    Waypoint4D,
)
from tests.mavlink.conftest import FakeVehicle, Sink

LAT, LON, ALT = 47.3977, 8.5456, 488.0  # FakeVehicle.position()'s default


def _track(
    tid: str, dlat_deg: float, *, op: str | None = None, icao: str | None = None, **kw: Any
) -> Track:
    return Track(
        id=TrackId(tid),
        t_s=0.0,
        lat_deg=LAT + dlat_deg,
        lon_deg=LON,
        alt_amsl_m=ALT + 20.0,
        east_m=0.0,
        north_m=0.0,
        vel_enu_mps=(3.0, 4.0, 1.0),
        position_sigma_m=1.0,
        cooperative=op is not None,
        operation_id=OperationId(op) if op else None,
        icao24=Icao24(icao) if icao else None,
        **kw,
    )


def _operation(op_id: str, sys_id: int) -> Operation:
    oid = OperationId(op_id)
    wp = Waypoint4D(lat_deg=LAT, lon_deg=LON, alt_amsl_m=ALT, t_s=0.0)
    return Operation(
        id=oid,
        icao24=None,
        sys_id=SysId(sys_id),
        priority=1,
        plan=FlightPlan(operation_id=oid, version=1, waypoints=(wp,)),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=10.0,
        operational_volume_m=30.0,
    )


TRACKS = {
    t.id: t
    for t in (
        _track("op-1", 0.001, op="op-1"),  # vehicle 1's own (its operation)
        _track("sysid:2", 0.002),  # vehicle 2, no operation
        _track("icao:abc123", 0.009, icao="abc123"),  # 1 km north
        _track("icao:def456", 0.2, icao="def456"),  # 22 km: out of the radius
        _track("icao:0badc0", 0.003, icao="0badc0", stale=True),
    )
}


async def _until(cond: Any, timeout_s: float = 3.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not cond():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.01)


@pytest.fixture
async def hub() -> Any:
    h = MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",)), RealClock(), sink := Sink())
    h.test_sink = sink  # type: ignore[attr-defined]
    await h.start()
    yield h
    await h.close()


async def _vehicle(hub: MavlinkHub, sys_id: int) -> FakeVehicle:
    port = hub.local_port(next(iter(hub.link_names())))
    v = await FakeVehicle(port, sys_id).start()
    v.heartbeat()
    v.position()
    await _until(lambda: hub._by_sysid.get(sys_id) is not None)
    await _until(lambda: hub.state(SysId(sys_id)).last_position is not None)
    return v


def _traffic(v: FakeVehicle) -> dict[int, Any]:
    return {m.ICAO_address: m for m in v.received if m.get_type() == "ADSB_VEHICLE"}


async def test_each_vehicle_gets_the_others_never_itself(hub: Any) -> None:
    v1, v2 = await _vehicle(hub, 1), await _vehicle(hub, 2)
    out = TrafficOut(
        TrafficOutConfig(enabled=True, radius_m=5000.0),
        hub,
        tracks=lambda: TRACKS,
        operations=lambda: [_operation("op-1", 1)],
    )
    out.tick()
    own1, own2 = icao_address(TRACKS[TrackId("op-1")]), icao_address(TRACKS[TrackId("sysid:2")])
    assert own1 >= SYNTHETIC_ICAO_BASE and own2 >= SYNTHETIC_ICAO_BASE and own1 != own2
    await _until(lambda: len(_traffic(v1)) == 2 and len(_traffic(v2)) == 2)
    assert set(_traffic(v1)) == {own2, 0xABC123}
    assert set(_traffic(v2)) == {own1, 0xABC123}
    m = _traffic(v1)[0xABC123]
    assert (m.lat, m.lon) == (round((LAT + 0.009) * 1e7), round(LON * 1e7))
    assert m.altitude_type == 1 and m.altitude == round((ALT + 20.0) * 1000)
    assert m.heading == 3687 and m.hor_velocity == 500 and m.ver_velocity == 100  # 36.87 deg
    assert m.callsign.rstrip("\x00") == "abc123" and m.emitter_type == 0
    u = _traffic(v1)[own2]
    assert u.emitter_type == 14 and u.callsign.rstrip("\x00") == "sysid:2"
    assert out.counters.sent == 4 and out.counters.send_errors == 0
    # vehicle 1 relays what it was told back (as ArduPilot's ADS-B stream does)
    v1.send(u, lossy=False)
    v1.send(m, lossy=False)
    await _until(lambda: hub.adsb_relay.counters.reports == 2)
    assert hub.adsb_relay.counters.echoes == 1  # the made-up address: dropped
    icaos = {x.icao24 for x in hub.test_sink.measurements if x.icao24 is not None}
    assert icaos == {"abc123"}  # a real intruder fuses with its own track
    v1.close()
    v2.close()


def test_disabled_by_default() -> None:
    assert TrafficOutConfig().enabled is False
