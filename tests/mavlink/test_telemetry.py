"""Telemetry -> measurements/status/hazards, link health, bad frames, identity, signing."""

from __future__ import annotations

import asyncio
import dataclasses
import os
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"

from adapters.mavlink import EndpointError, EndpointKind, parse_endpoint
from adapters.mavlink.wire import Encoder, Parser
from gcs_utm.model import Autopilot, SysId, ThreatKind, VehicleKind


async def _settle() -> None:
    await asyncio.sleep(0.05)


def test_parse_endpoint_forms_and_errors() -> None:
    assert parse_endpoint("udpin:0.0.0.0:14550").kind is EndpointKind.UDPIN
    e = parse_endpoint("udpout:10.0.0.2:14555")
    assert (e.kind, e.host, e.port) == (EndpointKind.UDPOUT, "10.0.0.2", 14555)
    assert parse_endpoint("tcp:localhost:5760").port == 5760
    s = parse_endpoint("/dev/ttyUSB0,57600")
    assert (s.kind, s.device, s.baud) == (EndpointKind.SERIAL, "/dev/ttyUSB0", 57600)
    assert parse_endpoint("/dev/ttyACM0:115200").baud == 115200
    for bad, part in [
        ("udpin:host:x", "port"),
        ("foo:1:2", "scheme"),
        ("udpout:h:0", "port"),
        ("/dev/ttyS0:123", "baud"),
        ("udpin:14550", "host"),
    ]:
        with pytest.raises(EndpointError) as ei:
            parse_endpoint(bad)
        assert ei.value.part == part, bad


def test_signed_frame_verifies_with_key_only() -> None:
    key = bytes(range(32))
    frame = Encoder(255, 190, key=key).command_long(1, 1, 176, 0, (1, 4, 3, 0, 0, 0, 0))
    assert frame[2] & 0x01  # MAVLINK_IFLAG_SIGNED
    good = Parser(key=key)
    [m] = good.feed(frame, datagram=True)
    assert m.command == 176 and m.param3 == 3
    bad = Parser(key=bytes(32))
    assert bad.feed(frame, datagram=True) == []
    assert bad.counters.bad_signature == 1


def test_parser_counts_bad_input_and_keeps_going() -> None:
    enc = Encoder(1, 1)
    good = enc.heartbeat(autopilot=12)
    p = Parser()
    assert p.feed(b"\x00garbage\xff" * 3, datagram=True) == []
    corrupt = bytearray(good)
    corrupt[-1] ^= 0xFF
    assert p.feed(bytes(corrupt), datagram=True) == []
    assert p.feed(good[:7], datagram=True) == []  # truncated
    unknown = bytearray(enc.heartbeat())
    unknown[7:10] = (60000).to_bytes(3, "little")  # message id nobody knows
    p.feed(bytes(unknown), datagram=True)
    assert len(p.feed(good, datagram=True)) == 1
    c = p.counters
    assert c.garbage >= 1 and c.bad_crc == 1 and c.truncated == 1 and c.unknown_msg == 1


async def test_discovery_position_capture_time_and_health(env: Any) -> None:
    v = await env.vehicle(1)
    info = env.sink.vehicles[0]
    assert info.autopilot is Autopilot.PX4 and info.vehicle_kind is VehicleKind.MULTIROTOR
    # SYSTEM_TIME maps vehicle boot time to UTC
    unix_s = 1_700_000_000.0
    v.send(v.mav.system_time_encode(int(unix_s * 1e6), 60_000), lossy=False)
    v.send(
        v.mav.gps_raw_int_encode(0, 3, 0, 0, 0, 80, 120, 0, 0, 12, 0, 1500, 2500, 0, 0), lossy=False
    )
    v.position(boot_ms=61_000)
    await _settle()
    m = env.sink.measurements[-1]
    assert m.sys_id == 1 and m.lat_deg == pytest.approx(47.3977) and m.alt_amsl_m == 488.0
    assert m.capture_t_s == pytest.approx(unix_s + 1.0)
    assert m.vel_ned_mps == (1.0, -2.0, 0.5) and m.eph_m == 1.5 and m.epv_m == 2.5
    # sequence gap -> loss; our heartbeats are unicast to the vehicle
    v.mav.seq = (v.mav.seq + 5) % 256
    v.position()
    await asyncio.sleep(0.25)
    h = [x for x in env.sink.health if x.sys_id == 1][-1]
    assert h.lost == 5 and h.received >= 4
    assert any(x.get_type() == "HEARTBEAT" for x in v.received)
    assert env.taps and env.taps[0][0] == env.link
    v.close()


async def test_bad_frames_counted_service_keeps_running(env: Any) -> None:
    v = await env.vehicle(2)
    v.send_raw(b"\xfd\x09garbage-without-crc")
    v.send_raw(b"hello world")
    v.position()
    await _settle()
    c = env.hub.counters
    assert c.truncated + c.garbage + c.bad_crc >= 2
    assert env.sink.measurements[-1].sys_id == 2
    v.close()


async def test_reboot_detected_and_duplicates_not_loss(env: Any) -> None:
    v = await env.vehicle(3)
    v.position(boot_ms=100_000)
    dup = v.mav.seq
    v.position(boot_ms=100_100)
    v.mav.seq = dup  # a duplicated datagram
    v.position(boot_ms=100_100)
    v.position(boot_ms=300)  # reboot
    await _settle()
    [h] = [x for x in env.hub.health() if x.sys_id == 3]
    assert h.reboots == 1 and h.lost == 0
    v.close()


async def test_battery_and_gnss_hazards(env: Any) -> None:
    v = await env.vehicle(4)
    sys_status = lambda pct: v.mav.sys_status_encode(0, 0, 0, 0, 15000, -1, pct, 0, 0, 0, 0, 0, 0)  # noqa: E731
    v.send(sys_status(60), lossy=False)
    v.send(sys_status(20), lossy=False)
    v.send(sys_status(19), lossy=False)  # still low: one hazard per episode
    gps = lambda fix, hacc: v.mav.gps_raw_int_encode(  # noqa: E731
        0, fix, 0, 0, 0, 80, 120, 0, 0, 12, 0, hacc, 2000, 0, 0
    )
    v.send(gps(3, 1000), lossy=False)
    v.send(gps(3, 9000), lossy=False)  # eph jump 1 -> 9 m
    v.send(gps(1, 9000), lossy=False)  # fix lost
    v.send(v.mav.statustext_encode(3, b"GPS jamming detected"), lossy=False)
    await _settle()
    kinds = [h.kind for h in env.sink.hazards if h.sys_id == 4]
    assert kinds == [
        ThreatKind.LACK_OF_BATTERY,
        ThreatKind.JAMMING_ATTACK,
        ThreatKind.GNSS_DEGRADATION,
        ThreatKind.JAMMING_ATTACK,
    ]
    v.close()


async def test_same_sysid_two_addresses_are_two_vehicles_with_unicast(env: Any) -> None:
    # a fleet that reuses system ids: without sysid binding (with it, b is a claim:
    # tests/mavlink/test_links_security.py)
    env.hub._senders.config = env.hub.config = dataclasses.replace(
        env.hub.config, sysid_binding=False
    )
    a = await env.vehicle(7)
    b = await env.vehicle(7)
    assert env.hub.counters.sysid_collisions == 1
    keys = {x.key for x in env.hub.vehicles() if x.key.sys_id == 7}
    assert len(keys) == 2
    kb = next(k for k in keys if k.address.endswith(f":{b.port}"))
    got = await env.hub.download_mission(kb)  # addressed by key: only b answers
    assert got == []
    assert not any(m.get_type() == "MISSION_REQUEST_LIST" for m in a.received)
    # each has its own link health, tagged with where it was first heard
    assert {h.vehicle for h in env.hub.health() if h.sys_id == 7} == {k.address for k in keys}
    assert {s.vehicle for s in env.sink.statuses if s.sys_id == 7} == {k.address for k in keys}
    a.close()
    b.close()


async def test_ardupilot_streams_requested(env: Any, fake_vehicle_cls: Any) -> None:
    v = await env.vehicle(11, autopilot=3)
    await _settle()
    intervals = [c for c in v.commands if c.command == 511]
    assert {int(c.param1) for c in intervals} >= {33, 24, 1, 2}
    assert any(m.get_type() == "REQUEST_DATA_STREAM" for m in v.received)
    assert env.hub.state(SysId(11)).autopilot is Autopilot.ARDUPILOT
    v.close()
