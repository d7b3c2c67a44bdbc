"""Independent check: MAVSDK 4 (native C++ MAVLink implementation, ctypes) plays the vehicle.

MAVSDK runs as an AUTOPILOT component that sends to our udpin link (``udpout://``). Its
``mission_raw_server`` must receive exactly the items our hub uploads (and answer our readback
download and MISSION_SET_CURRENT); its ``telemetry_server`` position must arrive as a
Measurement with the same numbers."""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from typing import Any

import pytest

from adapters.mavlink import MavlinkConfig, MavlinkHub, plan_to_mission_items
from gcs_utm.clock import RealClock
from gcs_utm.model import FlightPlan, OperationId, SysId, Waypoint4D
from tests.mavlink.conftest import Sink

pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.mission_raw_server import MissionRawServerAsync
from mavsdk.asyncio.plugins.telemetry_server import TelemetryServerAsync
from mavsdk.plugins.telemetry_server import Heading, Position, VelocityNed

pytestmark = [pytest.mark.network, pytest.mark.timeout(60)]


async def _until(cond: Callable[[], bool], timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out: {what}")
        await asyncio.sleep(0.02)


def _plan(n: int) -> FlightPlan:
    wps = tuple(
        Waypoint4D(lat_deg=47.3977 + 0.0005 * i, lon_deg=8.5456, alt_amsl_m=500.0 + i, t_s=10.0 * i)
        for i in range(n)
    )
    return FlightPlan(operation_id=OperationId("op-mavsdk"), version=1, waypoints=wps)


async def _collect(gen: Any, out: list[Any]) -> None:
    async for x in gen:
        out.append(x)


async def test_mavsdk_vehicle_receives_our_mission_and_sends_telemetry() -> None:
    sink = Sink()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2)
    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        port = hub.local_port(next(iter(hub._links)))
        mcfg = Configuration.create_with_component_type(ComponentType.AUTOPILOT)
        async with Mavsdk(mcfg) as vehicle:
            await vehicle.add_any_connection(f"udpout://127.0.0.1:{port}")
            component = await vehicle.server_component()
            assert component is not None
            missions = MissionRawServerAsync(component)
            telemetry = TelemetryServerAsync(component)
            incoming: list[Any] = []
            currents: list[Any] = []
            tasks = [
                asyncio.create_task(_collect(missions.subscribe_incoming_mission(), incoming)),
                asyncio.create_task(_collect(missions.subscribe_current_item_changed(), currents)),
            ]
            try:
                await _until(lambda: bool(sink.vehicles), 5.0, "MAVSDK vehicle not discovered")
                info = sink.vehicles[0]
                assert info.key.sys_id == 1 and info.key.comp_id == 1

                # telemetry: TelemetryServer.publish_position -> GLOBAL_POSITION_INT
                await telemetry.publish_position(
                    Position(47.3981234, 8.5467891, 512.25, 24.0),
                    VelocityNed(1.5, -2.25, 0.5),
                    Heading(90.0),
                )
                await _until(lambda: bool(sink.measurements), 3.0, "no measurement")
                m = sink.measurements[-1]
                assert (m.lat_deg, m.lon_deg) == pytest.approx((47.3981234, 8.5467891), abs=1e-7)
                assert m.alt_amsl_m == pytest.approx(512.25, abs=1e-3)
                assert m.vel_ned_mps == pytest.approx((1.5, -2.25, 0.5), abs=0.01)
                assert m.sys_id == 1

                # mission: exactly our items arrive, readback and set-current work
                plan = _plan(6)
                res = await hub.upload_plan(SysId(1), plan, start_index=2, set_mission_mode=False)
                assert res.ok and res.verified and res.current_set, res
                await _until(lambda: bool(incoming), 3.0, "mission_raw_server got nothing")
                result, mission = incoming[-1]
                assert result.name == "SUCCESS", result
                sent = plan_to_mission_items(plan, start_index=2)
                got = mission.mission_items
                assert len(got) == len(sent)
                for g, s in zip(got, sent, strict=True):
                    assert (g.seq, g.frame, g.command, g.current, g.autocontinue) == (
                        s.seq,
                        s.frame,
                        s.command,
                        s.current,
                        s.autocontinue,
                    )
                    assert (g.x, g.y, g.mission_type) == (s.x, s.y, 0)
                    assert g.z == pytest.approx(s.z, abs=1e-4)
                    for name in ("param1", "param2", "param3", "param4"):
                        a, b = getattr(g, name), getattr(s, name)
                        assert (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b), name
                cur = next(s.seq for s in sent if s.current)
                await _until(lambda: any(c.seq == cur for c in currents), 3.0, "current item")
                assert hub.counters.bad_crc == 0 and hub.counters.handler_errors == 0
            finally:
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
                missions.destroy()
                telemetry.destroy()
