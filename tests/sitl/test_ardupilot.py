"""ArduPilot personality over TCP: streams on request, seq 0 = home, ArduPilot mode numbers."""

from __future__ import annotations

import asyncio
from typing import Any

import sitl
from tests.sitl.conftest import WP, mav


async def _collect(reader: asyncio.StreamReader, dec: Any, out: list[Any], secs: float) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + secs
    while (left := end - loop.time()) > 0:
        try:
            data = await asyncio.wait_for(reader.read(4096), left)
        except TimeoutError:
            return
        out.extend(dec.parse_buffer(data) or [])


async def test_ardupilot_copter_over_tcp() -> None:
    spec = sitl.VehicleSpec(instance=2, autopilot="ardupilot", tcp_port=0, mission=WP)
    async with sitl.Fleet([spec], sitl.SimTime(speed=4.0)) as fleet:
        v = fleet.vehicles[0]
        assert v.local_port == 0 and v.tcp_port > 0  # no UDP unless asked for
        reader, writer = await asyncio.open_connection("127.0.0.1", v.tcp_port)
        enc = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        dec = mav.MAVLink(None)
        msgs: list[Any] = []
        await _collect(reader, dec, msgs, 0.8)
        kinds = {m.get_type() for m in msgs}
        assert "HEARTBEAT" in kinds and "GLOBAL_POSITION_INT" not in kinds
        hb = next(m for m in msgs if m.get_type() == "HEARTBEAT")
        # STABILIZE (0): real ArduCopter boots in it
        assert hb.autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA and hb.custom_mode == 0
        assert hb.get_srcSystem() == 3
        writer.write(mav.MAVLink_request_data_stream_message(3, 1, 0, 4, 1).pack(enc))
        writer.write(
            mav.MAVLink_command_long_message(
                3, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0
            ).pack(enc)
        )
        writer.write(mav.MAVLink_mission_request_list_message(3, 1, 0).pack(enc))
        writer.write(mav.MAVLink_mission_request_int_message(3, 1, 0, 0).pack(enc))
        await writer.drain()
        msgs.clear()
        await _collect(reader, dec, msgs, 1.0)
        kinds = {m.get_type() for m in msgs}
        assert {"GLOBAL_POSITION_INT", "SYS_STATUS", "ATTITUDE"} <= kinds
        count = next(m for m in msgs if m.get_type() == "MISSION_COUNT")
        assert count.count == 5  # home + speed item + 3 waypoints
        home = next(m for m in msgs if m.get_type() == "MISSION_ITEM_INT")
        assert home.seq == 0 and home.x == round(spec.home_lat_deg * 1e7)
        assert v.mode == "GUIDED"
        assert any(m.get_type() == "HEARTBEAT" and m.custom_mode == 4 for m in msgs)
        # As ArduPilot 4.6: EXTENDED_SYS_STATE is in no stream group, only asked for by id
        assert "EXTENDED_SYS_STATE" not in kinds
        writer.write(
            mav.MAVLink_command_long_message(
                3, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 245, 250_000, 0, 0, 0, 0, 0
            ).pack(enc)
        )
        await writer.drain()
        msgs.clear()
        await _collect(reader, dec, msgs, 1.0)
        ess = [m for m in msgs if m.get_type() == "EXTENDED_SYS_STATE"]
        assert ess and ess[-1].landed_state == mav.MAV_LANDED_STATE_ON_GROUND
        writer.close()
        await writer.wait_closed()


def test_plane_mode_numbers() -> None:
    from sitl.vehicle import PLANE_MODES, Vehicle

    v = Vehicle(
        sitl.VehicleSpec(instance=0, autopilot="ardupilot", kind="fixed_wing"), sitl.SimTime()
    )
    assert v.commands.set_mode_numbers(1, 11) == 0 and v.mode == "RTL" and PLANE_MODES["RTL"] == 11
    assert v.telemetry.custom_mode()[1] == 11
    assert v.commands.set_mode_numbers(1, 99) == mav.MAV_RESULT_UNSUPPORTED
