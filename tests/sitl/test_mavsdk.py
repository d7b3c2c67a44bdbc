"""Independent check: MAVSDK 4 (native C++ MAVLink implementation) as the ground station."""

from __future__ import annotations

import asyncio
import socket

import pytest

import sitl

mavsdk = pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.autopilot import Autopilot  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem  # noqa: E402


def _free_udp_port() -> int:
    # MAVSDK binds the port itself (udpin://); a just-released ephemeral port is the best we can do.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _item(seq: int, lat: float, lon: float, rel_alt: float) -> MissionItem:
    return MissionItem(
        seq,
        6,
        16,
        1 if seq == 0 else 0,
        1,
        0.0,
        2.0,
        0.0,
        float("nan"),
        round(lat * 1e7),
        round(lon * 1e7),
        rel_alt,
        0,
    )


async def test_mavsdk_sees_px4_and_flies_the_protocol() -> None:
    port = _free_udp_port()
    spec = sitl.VehicleSpec(instance=0, gcs_port=port, bind_port=0)
    async with sitl.Fleet([spec], sitl.SimTime(speed=5.0)) as fleet:
        v = fleet.vehicles[0]
        cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(cfg) as m:
            await m.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await m.first_autopilot(timeout_s=5.0)
            assert system is not None
            assert await system.autopilot_type() == Autopilot.PX4
            assert await system.get_system_id() == 1
            mission = MissionRawAsync(system)
            action = ActionAsync(system)
            items = [_item(i, 47.3980 + 0.0002 * i, 8.5456, 20.0) for i in range(3)]
            await mission.upload_mission(items)
            assert len(v.mission) == 3 and v.counters["uploads_ok"] == 1
            down = await mission.download_mission()
            assert [(d.seq, d.x, d.y) for d in down] == [(i.seq, i.x, i.y) for i in items]
            await mission.set_current_mission_item(1)
            assert v.mission_current_seq == 1
            await action.arm()
            assert v.armed
            await mission.start_mission()
            assert v.mode == "MISSION"
            await asyncio.sleep(1.0)
            assert not v.landed
            await action.hold()
            assert v.mode == "HOLD"
            await action.return_to_launch()
            assert v.mode == "RTL"
            await action.land()
            assert v.mode == "LAND"
            assert v.counters["handler_errors"] == 0 and v.counters["bad_crc"] == 0
