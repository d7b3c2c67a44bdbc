"""Wire behaviour of a PX4-like instance, checked with raw pymavlink from the test side."""

from __future__ import annotations

import asyncio

import sitl
from tests.sitl.conftest import RawGcs, mav, px4_spec


async def test_heartbeat_streams_and_identity(gcs: RawGcs) -> None:
    spec = px4_spec(gcs.port, instance=3)
    async with sitl.Fleet([spec], sitl.SimTime(speed=4.0)) as fleet:
        v = fleet.vehicles[0]
        hb = await gcs.wait_type("HEARTBEAT", start=0)
        assert hb.get_srcSystem() == 4 and hb.get_srcComponent() == 1
        assert hb.autopilot == mav.MAV_AUTOPILOT_PX4 and hb.type == mav.MAV_TYPE_QUADROTOR
        assert hb.custom_mode == (4 << 16) | (3 << 24)  # AUTO.LOITER (hold)
        assert not hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
        # sent from the bound port to our port before we ever spoke
        assert ("127.0.0.1", v.local_port) in gcs.senders
        for kind in (
            "GLOBAL_POSITION_INT",
            "GPS_RAW_INT",
            "SYS_STATUS",
            "BATTERY_STATUS",
            "EXTENDED_SYS_STATE",
            "HOME_POSITION",
            "MISSION_CURRENT",
            "ATTITUDE",
            "SYSTEM_TIME",
            "STATUSTEXT",
        ):
            await gcs.wait_type(kind, start=0)
        gps = await gcs.wait_type("GPS_RAW_INT", start=0)
        assert gps.fix_type == 3 and gps.satellites_visible > 6
        assert all(m.get_header().mlen is not None for m in gcs.msgs)
        assert gcs.msgs[0]._header.srcSystem == 4


async def test_time_is_consistent_with_simtime(gcs: RawGcs) -> None:
    clock = sitl.SimTime(speed=10.0, start_utc_s=1_700_000_000.0)
    async with sitl.Fleet([px4_spec(gcs.port)], clock):
        st = await gcs.wait_type("SYSTEM_TIME", start=0)
        st2 = await gcs.wait_type("SYSTEM_TIME")
        assert abs(st.time_unix_usec / 1e6 - clock.now_s()) < 1.5  # one tick at speed 10
        d_unix = (st2.time_unix_usec - st.time_unix_usec) / 1e6
        d_boot = (st2.time_boot_ms - st.time_boot_ms) / 1e3
        assert abs(d_unix - d_boot) < 0.06
        assert st.time_unix_usec / 1e6 - 1_700_000_000.0 - st.time_boot_ms / 1e3 < 0.1


async def test_reply_address_learned_and_other_sysid_dropped(gcs: RawGcs) -> None:
    async with sitl.Fleet([px4_spec(9)], sitl.SimTime(speed=2.0)) as fleet:  # GCS port 9: nobody
        v = fleet.vehicles[0]
        gcs.send(v.local_port, mav.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        await gcs.wait_type("HEARTBEAT", start=0)  # now it answers to us
        cmd = mav.MAVLink_command_long_message(
            7, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
        )
        gcs.send(v.local_port, cmd)
        await asyncio.sleep(0.2)
        assert v.counters["dropped_other_sysid"] == 1 and not v.armed
        with_ack = len(gcs.msgs)
        gcs.send(
            v.local_port, mav.MAVLink_command_long_message(1, 1, 31000, 0, 0, 0, 0, 0, 0, 0, 0)
        )
        ack = await gcs.wait_type("COMMAND_ACK", start=with_ack)
        assert ack.command == 31000 and ack.result == mav.MAV_RESULT_UNSUPPORTED
        assert v.counters["unsupported_cmd"] == 1


async def test_bad_input_is_counted_and_vehicle_survives(gcs: RawGcs) -> None:
    async with sitl.Fleet([px4_spec(gcs.port)], sitl.SimTime(speed=2.0)) as fleet:
        v = fleet.vehicles[0]
        port = v.local_port
        good = mav.MAVLink_command_long_message(
            1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
        ).pack(gcs.enc)
        gcs.raw(port, b"\x00\x01garbage bytes\x02" * 3)
        bad_crc = bytearray(good)
        bad_crc[-1] ^= 0xFF
        gcs.raw(port, bytes(bad_crc))
        gcs.raw(port, good[: len(good) // 2])  # truncated frame at the end of a datagram
        unknown = bytearray(mav.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(gcs.enc))
        unknown[7:10] = (40000).to_bytes(3, "little")  # message id nobody knows
        gcs.raw(port, bytes(unknown))
        gcs.raw(port, b"")
        gcs.raw(port, bytes(range(256)) * 4)
        await asyncio.sleep(0.3)
        c = v.counters
        assert c["garbage"] >= 1 and c["bad_crc"] >= 1 and c["truncated"] >= 1
        assert c["unknown_msgid"] + c["bad_crc"] >= 2
        assert c["handler_errors"] == 0
        # still alive and answering after all that
        start = len(gcs.msgs)
        gcs.send(
            port,
            mav.MAVLink_command_long_message(
                1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
            ),
        )
        ack = await gcs.wait_type("COMMAND_ACK", start=start)
        assert ack.result == mav.MAV_RESULT_ACCEPTED and v.armed
