"""Mission protocol, vehicle side, against a raw pymavlink ground station."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

import sitl
from sitl import mission as mp
from tests.sitl.conftest import WP, RawGcs, mav, px4_spec


def item(
    seq: int, lat: float, lon: float, alt: float, *, cmd: int = 16, frame: int = 5, current: int = 0
) -> Any:
    return mav.MAVLink_mission_item_int_message(
        1,
        1,
        seq,
        frame,
        cmd,
        current,
        1,
        0,
        0,
        0,
        float("nan"),
        round(lat * 1e7),
        round(lon * 1e7),
        alt,
        0,
    )


def square(n: int = 3) -> list[Any]:
    return [item(i, 47.3980 + 0.0002 * i, 8.5456, 500.0) for i in range(n)]


async def upload(gcs: RawGcs, port: int, items: list[Any]) -> Any:
    start = len(gcs.msgs)
    gcs.send(port, mav.MAVLink_mission_count_message(1, 1, len(items), 0))
    while True:
        m = await gcs.wait(
            lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK"), start=start
        )
        start = gcs.last_index
        if m.get_type() == "MISSION_ACK":
            return m
        gcs.send(port, items[m.seq])


async def test_upload_download_roundtrip_and_old_request(gcs: RawGcs) -> None:
    async with sitl.Fleet([px4_spec(gcs.port)], sitl.SimTime(speed=2.0)) as fleet:
        v = fleet.vehicles[0]
        ack = await upload(gcs, v.local_port, square(4))
        assert ack.type == mav.MAV_MISSION_ACCEPTED and len(v.mission) == 4
        assert v.counters["uploads_ok"] == 1
        start = len(gcs.msgs)
        gcs.send(v.local_port, mav.MAVLink_mission_request_list_message(1, 1, 0))
        cnt = await gcs.wait_type("MISSION_COUNT", start=start)
        assert cnt.count == 4
        gcs.send(v.local_port, mav.MAVLink_mission_request_int_message(1, 1, 0, 0))
        it = await gcs.wait_type("MISSION_ITEM_INT", start=start)
        assert it.seq == 0 and it.x == round(47.3980 * 1e7)
        for _ in range(2):  # the second one is a re-request (our item was "lost"): answered
            start = len(gcs.msgs)
            gcs.send(v.local_port, mav.MAVLink_mission_request_message(1, 1, 1, 0))  # old peer
            old = await gcs.wait_type("MISSION_ITEM", start=start)
            assert old.seq == 1 and old.x == pytest.approx(47.3982, abs=1e-6)
        # PX4 answers only the expected request or a repeat of the last one: no pipelining
        gcs.send(v.local_port, mav.MAVLink_mission_request_int_message(1, 1, 3, 0))
        bad = await gcs.wait_type("MISSION_ACK", start=start)
        assert bad.type == mav.MAV_MISSION_ERROR
        start = len(gcs.msgs)
        gcs.send(v.local_port, mav.MAVLink_mission_request_list_message(1, 1, 0))
        await gcs.wait_type("MISSION_COUNT", start=start)
        gcs.send(v.local_port, mav.MAVLink_mission_request_int_message(1, 1, 9, 0))
        bad = await gcs.wait_type("MISSION_ACK", start=start)
        assert bad.type == mav.MAV_MISSION_ERROR


async def test_upload_result_codes(gcs: RawGcs) -> None:
    async with sitl.Fleet([px4_spec(gcs.port, max_mission_items=10)], sitl.SimTime()) as fleet:
        port = fleet.vehicles[0].local_port
        s = len(gcs.msgs)
        gcs.send(port, mav.MAVLink_mission_count_message(1, 1, 11, 0))
        assert (await gcs.wait_type("MISSION_ACK", start=s)).type == mav.MAV_MISSION_NO_SPACE
        s = len(gcs.msgs)
        gcs.send(port, mav.MAVLink_mission_count_message(1, 1, 2, mav.MAV_MISSION_TYPE_FENCE))
        assert (await gcs.wait_type("MISSION_ACK", start=s)).type == mav.MAV_MISSION_UNSUPPORTED
        ack = await upload(
            gcs,
            port,
            [square(1)[0], item(1, 47.4, 8.5, 500, cmd=mav.MAV_CMD_DO_SET_SERVO, frame=2)],
        )
        assert ack.type == mav.MAV_MISSION_UNSUPPORTED
        ack = await upload(gcs, port, [item(0, 47.4, 8.5, 500, frame=mav.MAV_FRAME_LOCAL_NED)])
        assert ack.type == mav.MAV_MISSION_UNSUPPORTED_FRAME
        ack = await upload(gcs, port, [item(0, 95.0, 8.5, 500)])
        assert ack.type == mav.MAV_MISSION_INVALID_PARAM5_X
        # an item it did not ask for during an upload: PX4 ignores it and asks again
        s = len(gcs.msgs)
        gcs.send(port, mav.MAVLink_mission_count_message(1, 1, 2, 0))
        await gcs.wait_type("MISSION_REQUEST_INT", start=s)
        s = len(gcs.msgs)
        gcs.send(port, item(7, 47.4, 8.5, 500))
        again = await gcs.wait(
            lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK"), start=s
        )
        assert again.get_type() == "MISSION_REQUEST_INT" and again.seq == 0
        assert fleet.vehicles[0].counters["mission_bad_seq"] == 1
        assert fleet.vehicles[0].mission == ()
        assert fleet.vehicles[0].counters["uploads_failed"] >= 4


async def test_rerequest_timeout_and_repeated_ack(
    gcs: RawGcs, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(mp, "PROTOCOL_TIMEOUT_S", 0.8)
    async with sitl.Fleet([px4_spec(gcs.port)], sitl.SimTime()) as fleet:
        v = fleet.vehicles[0]
        s = len(gcs.msgs)
        gcs.send(v.local_port, mav.MAVLink_mission_count_message(1, 1, 2, 0))
        await asyncio.sleep(0.6)
        reqs = [m for m in gcs.msgs[s:] if m.get_type() == "MISSION_REQUEST_INT"]
        assert 2 <= len(reqs) <= 4 and all(r.seq == 0 for r in reqs)  # every 250 ms
        txt = await gcs.wait(
            lambda m: m.get_type() == "STATUSTEXT" and "timeout" in str(m.text),
            start=s,
            timeout=2.0,
        )
        assert txt.severity == mav.MAV_SEVERITY_CRITICAL
        assert v.mission == () and v.counters["uploads_failed"] == 1
        items = square(2)
        ack = await upload(gcs, v.local_port, items)
        assert ack.type == 0
        s = len(gcs.msgs)
        gcs.send(v.local_port, items[1])  # our ACK got lost: the ground repeats the last item
        assert (await gcs.wait_type("MISSION_ACK", start=s)).type == 0
        assert v.counters["mission_repeated_ack"] == 1 and v.counters["uploads_ok"] == 1


async def test_clear_set_current_and_inflight_upload_keeps_index(gcs: RawGcs) -> None:
    spec = px4_spec(gcs.port, mission=WP, auto_start_at_s=0.0)
    async with sitl.Fleet([spec], sitl.SimTime(speed=20.0)) as fleet:
        v = fleet.vehicles[0]
        port = v.local_port
        # preloaded: speed item + 3 waypoints = 4 items
        assert len(v.mission) == 4
        s = len(gcs.msgs)
        gcs.send(port, mav.MAVLink_mission_set_current_message(1, 1, 3))
        cur = await gcs.wait(lambda m: m.get_type() == "MISSION_CURRENT" and m.seq == 3, start=s)
        assert cur.total == 4
        assert v.mode == "MISSION" and v.armed
        # in-flight upload without a current flag keeps index 3
        ack = await upload(gcs, port, square(5))
        assert ack.type == 0 and v.mission_current_seq == 3
        # ... and with a flag on item 1 switches to it
        items = square(5)
        items[1] = item(1, 47.3982, 8.5456, 500.0, current=1)
        await upload(gcs, port, items)
        assert v.mission_current_seq == 1
        gcs.send(port, mav.MAVLink_mission_set_current_message(1, 1, 42))
        await gcs.wait(
            lambda m: m.get_type() == "STATUSTEXT" and "out of bounds" in str(m.text), start=s
        )
        s = len(gcs.msgs)
        gcs.send(port, mav.MAVLink_mission_clear_all_message(1, 1, 0))
        assert (await gcs.wait_type("MISSION_ACK", start=s)).type == 0
        assert v.mission == () and v.mode == "HOLD"


async def storage_up(v: sitl.Vehicle) -> None:
    """ArduPilot refuses uploads (NO_SPACE) for ~1.5 simulated s after boot."""
    while not v.storage_ready():
        await asyncio.sleep(0.05)


async def test_ardupilot_upload_nacks_unexpected_items_and_keeps_receiving(gcs: RawGcs) -> None:
    """ArduPilot's MissionItemProtocol: an item it did not ask for gets
    MAV_MISSION_INVALID_SEQUENCE and the transfer goes on; once the upload is complete a
    repeated item gets MAV_MISSION_ERROR (not a repeated ACCEPTED, as PX4 sends)."""
    spec = px4_spec(gcs.port, autopilot="ardupilot")
    async with sitl.Fleet([spec], sitl.SimTime()) as fleet:
        v = fleet.vehicles[0]
        await storage_up(v)
        items = square(3)
        s = len(gcs.msgs)
        gcs.send(v.local_port, mav.MAVLink_mission_count_message(1, 1, 3, 0))
        await gcs.wait_type("MISSION_REQUEST_INT", start=s, seq=0)
        s = len(gcs.msgs)
        gcs.send(v.local_port, items[1])  # ahead of the request
        nack = await gcs.wait_type("MISSION_ACK", start=s)
        assert nack.type == mav.MAV_MISSION_INVALID_SEQUENCE
        ack = await upload_from(gcs, v.local_port, items, start=s)
        assert ack.type == mav.MAV_MISSION_ACCEPTED and len(v.mission) == 3
        s = len(gcs.msgs)
        gcs.send(v.local_port, items[2])  # as if our ACCEPTED had been lost
        late = await gcs.wait_type("MISSION_ACK", start=s)
        assert late.type == mav.MAV_MISSION_ERROR and len(v.mission) == 3


async def upload_from(gcs: RawGcs, port: int, items: list[Any], *, start: int) -> Any:
    """Answer the vehicle's requests from message index ``start`` until its ACCEPTED."""
    while True:
        m = await gcs.wait(
            lambda m: (
                m.get_type() == "MISSION_REQUEST_INT"
                or (m.get_type() == "MISSION_ACK" and m.type == mav.MAV_MISSION_ACCEPTED)
            ),
            start=start,
        )
        start = gcs.last_index
        if m.get_type() == "MISSION_ACK":
            return m
        gcs.send(port, items[m.seq])


async def test_ardupilot_rerequests_every_second(gcs: RawGcs) -> None:
    spec = px4_spec(gcs.port, autopilot="ardupilot")
    async with sitl.Fleet([spec], sitl.SimTime()) as fleet:
        v = fleet.vehicles[0]
        await storage_up(v)
        s = len(gcs.msgs)
        gcs.send(v.local_port, mav.MAVLink_mission_count_message(1, 1, 2, 0))
        await gcs.wait_type("MISSION_REQUEST_INT", start=s, seq=0)
        await asyncio.sleep(0.7)  # PX4 would have asked twice more by now
        assert v.counters["mission_rerequests"] == 0
        await gcs.wait_type("MISSION_REQUEST_INT", start=gcs.last_index, seq=0)
        assert v.counters["mission_rerequests"] == 1
