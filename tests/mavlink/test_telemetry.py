"""Telemetry -> measurements/status/hazards, link health, bad frames, identity, signing."""

from __future__ import annotations

import asyncio
import dataclasses
import os
import random
import time
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"

from fastcrc import crc16
from pymavlink.dialects.v20 import common as mav_common
from pymavlink.dialects.v20.common import MAVLINK_MSG_ID_MISSION_CURRENT

from adapters.mavlink import EndpointError, EndpointKind, MavlinkConfig, parse_endpoint
from adapters.mavlink.vehicle import VehicleState
from adapters.mavlink.wire import Encoder, Parser
from gcs_utm.messages import VehicleKey
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
    # SYSTEM_TIME that agrees with its arrival (0.3 s old) maps vehicle boot time to UTC
    unix_s = time.time() - 0.3
    v.send(v.mav.system_time_encode(int(unix_s * 1e6), 60_000), lossy=False)
    v.send(
        v.mav.gps_raw_int_encode(0, 3, 0, 0, 0, 80, 120, 0, 0, 12, 0, 1500, 2500, 0, 0), lossy=False
    )
    v.position(boot_ms=60_050)
    await _settle()
    m = env.sink.measurements[-1]
    assert m.sys_id == 1 and m.lat_deg == pytest.approx(47.3977) and m.alt_amsl_m == 488.0
    assert m.capture_t_s == pytest.approx(unix_s + 0.05, abs=1e-6)
    assert env.hub.state(SysId(1)).system_time_used == 1
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


async def test_ardupilot_asked_again_while_it_sends_no_position(
    env: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A request lost or undone while the autopilot boots (ArduPilot SITL reloads its
    parameter defaults, the stream rates among them): a vehicle that heartbeats without a
    position is asked again, not left silent for good."""
    import adapters.mavlink.hub as hub_module

    monkeypatch.setattr(hub_module, "STREAM_RETRY_S", 0.2)
    v = await env.vehicle(12, autopilot=3)
    await _settle()

    def asked() -> int:
        return sum(m.get_type() == "REQUEST_DATA_STREAM" for m in v.received)

    first = asked()
    assert first >= 1
    await asyncio.sleep(0.3)
    v.heartbeat()
    await _settle()
    assert asked() > first
    v.close()


async def test_ardupilot_restarted_after_positions_is_asked_again(
    env: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An ArduPilot that sent positions, then rebooted (its clock back) and, its new
    request undone while it booted, sends only heartbeats: asked again, as a vehicle that
    never sent a position is (on CI a restarted ArduCopter stayed silent for good)."""
    import adapters.mavlink.hub as hub_module

    monkeypatch.setattr(hub_module, "STREAM_RETRY_S", 0.2)
    v = await env.vehicle(13, autopilot=3)
    for k in range(3):
        v.position(boot_ms=60_000 + 100 * k)
    await _settle()

    def asked() -> int:
        return sum(m.get_type() == "REQUEST_DATA_STREAM" for m in v.received)

    await asyncio.sleep(0.3)
    v.heartbeat()  # positions came after the first request: not asked again
    await _settle()
    first = asked()
    v.position(boot_ms=2_000)  # the new life's first report: a reboot, asked at once
    await _settle()
    assert env.hub.state(SysId(13)).reboots == 1 and asked() > first
    rebooted = asked()
    await asyncio.sleep(0.3)
    v.heartbeat()  # no position since: asked again
    await _settle()
    assert asked() > rebooted
    v.close()


# ---- the vehicle clock filter (VehicleState, no sockets) -----------------------------------


class _Events:
    def __init__(self) -> None:
        self.measurements: list[Any] = []

    def on_measurement(self, m: Any) -> None:
        self.measurements.append(m)

    def on_status(self, s: Any) -> None:
        pass

    def on_hazard(self, h: Any) -> None:
        pass

    def on_vehicle(self, v: Any) -> None:
        pass

    def on_link_health(self, h: Any) -> None:
        pass


def _clock_state(**cfg: Any) -> tuple[VehicleState, _Events]:
    key = VehicleKey(link="test", address="127.0.0.1:1", sys_id=SysId(1))
    return VehicleState(key, MavlinkConfig(**cfg), 0.0), _Events()


def _report(st: VehicleState, ev: _Events, boot_ms: int, receipt_t_s: float) -> Any:
    st.on_global_position((boot_ms, 473977000, 85456000, 488000, 0, 0, 0, 0, 0), receipt_t_s, ev)
    return ev.measurements[-1]


def _fly(
    st: VehicleState,
    ev: _Events,
    *,
    seconds: float,
    rate: float,
    t0_s: float = 1000.0,
    boot0_ms: int = 30_000,
    seed: int = 1,
) -> list[float]:
    """Positions at 50 Hz from a vehicle whose clock runs at ``rate`` x ours, each delayed
    0-20 ms (and one in 100 by 300 ms); returns receipt - capture of every report."""
    rng = random.Random(seed)
    lags: list[float] = []
    for k in range(int(seconds * 50)):
        true_t = t0_s + k * 0.02
        boot_ms = boot0_ms + round(k * 20 * rate)
        delay = 0.3 if k % 100 == 37 else rng.uniform(0.0, 0.02)
        m = _report(st, ev, boot_ms, true_t + delay)
        lags.append(m.receipt_t_s - m.capture_t_s)
    return lags


@pytest.mark.parametrize("rate", [0.99, 0.97, 1.0, 1.01])
def test_clock_drift_followed_capture_never_after_receipt(rate: float) -> None:
    """PX4 SIH's clock runs ~1 % slow: an offset anchored once (the minimum of receipt - boot)
    lags by 1 s per 100 s and the track goes stale after ~8 min; the filter follows drift of
    a few % in either direction and never dates a report after its arrival."""
    st, ev = _clock_state()
    lags = _fly(st, ev, seconds=900.0, rate=rate)
    assert min(lags) >= -1e-9  # (float rounding of receipt - boot + boot)
    tail = sorted(lags[-3000:])  # the last minute
    # median: the transport jitter plus at most two windows of drift (1 s x 3 % x 2)
    assert tail[len(tail) // 2] < 0.08
    assert tail[-1] < 0.4  # at worst the 300 ms delayed report (+ the drift lag)
    assert st.clock_jumps == 0


def test_position_without_altitude_is_no_measurement() -> None:
    """PX4 reports alt = INT32_MIN (-2147483.648 m) when it has no altitude: not a position."""
    st, ev = _clock_state()
    st.on_global_position((30_000, 473977000, 85456000, -(2**31), 0, 0, 0, 0, 0), 1000.0, ev)
    assert ev.measurements == []
    assert st.last_position is None
    assert _report(st, ev, 30_020, 1000.02).alt_amsl_m == 488.0


def test_clock_drift_beyond_the_bound_re_anchored() -> None:
    """A simulator that cannot keep its speed factor (its clock at 0.8 x ours): the rise is
    too slow, so whole windows arrive late and the offset is re-anchored (counted); reports
    stay within clock_jump_s + two windows of excess drift (0.5 + 2 x 1 s x 0.15) and the
    300 ms late reports of their arrival, never after it."""
    st, ev = _clock_state()
    lags = _fly(st, ev, seconds=300.0, rate=0.8)
    assert min(lags) >= -1e-9
    assert max(lags[50 * 10 :]) < 1.2
    assert st.clock_jumps > 10


def test_clock_one_late_report_does_not_move_the_offset() -> None:
    st, ev = _clock_state()
    _fly(st, ev, seconds=10.0, rate=1.0)
    off = st.offset_s
    assert off is not None
    m = _report(st, ev, st.last_boot_ms + 20, 1010.0 + 0.8)  # 0.8 s late
    assert m.receipt_t_s - m.capture_t_s == pytest.approx(0.8, abs=0.03)
    assert st.offset_s == pytest.approx(off, abs=0.002)


def test_clock_jump_back_re_anchored_and_counted() -> None:
    """time_boot_ms steps back 1.5 s (less than a reboot): reports would be dated 1.5 s early
    (stale tracks); within two clock windows the offset is re-anchored."""
    st, ev = _clock_state()
    _fly(st, ev, seconds=20.0, rate=1.0)
    lags = _fly(st, ev, seconds=20.0, rate=1.0, t0_s=1020.0, boot0_ms=30_000 + 20_000 - 1500)
    assert st.clock_jumps == 1 and st.reboots == 0
    assert max(lags[50 * 5 :]) < 0.35  # after 5 s
    assert max(lags[:50]) > 1.4  # it did jump


def test_clock_jump_forward_never_dates_after_receipt() -> None:
    st, ev = _clock_state()
    _fly(st, ev, seconds=5.0, rate=1.0)
    lags = _fly(st, ev, seconds=5.0, rate=1.0, t0_s=1005.0, boot0_ms=30_000 + 5_000 + 7_000)
    assert min(lags) >= -1e-9  # (float rounding of receipt - boot + boot) and max(lags[1:]) < 0.35


def test_clock_reboot_starts_over() -> None:
    st, ev = _clock_state()
    _fly(st, ev, seconds=100.0, rate=0.99)
    m = _report(st, ev, 300, 1100.0)
    assert st.reboots == 1
    assert m.capture_t_s == pytest.approx(1100.0)
    lags = _fly(st, ev, seconds=30.0, rate=1.0, t0_s=1100.02, boot0_ms=320)
    assert (
        min(lags) >= -1e-9
    )  # (float rounding of receipt - boot + boot) and sorted(lags)[len(lags) // 2] < 0.03


@pytest.mark.parametrize(("lag_s", "used"), [(0.2, True), (3.84, False), (-0.5, False)])
def test_system_time_used_only_when_it_agrees_with_arrivals(lag_s: float, used: bool) -> None:
    """ArduPilot SITL's SYSTEM_TIME lagged the host clock by 3.84 s; trusted, its track ran
    ~4 s ahead. A SYSTEM_TIME at most system_time_max_lag_s older than its arrival is used
    (it removes the transport delay); otherwise counted and corrected from arrivals."""
    st, ev = _clock_state()
    t0 = 1_700_000_000.0  # SYSTEM_TIME before 2017 means "no GNSS time yet"
    _fly(st, ev, seconds=5.0, rate=1.0, t0_s=t0)
    boot_ms = st.last_boot_ms + 10
    receipt = t0 + (boot_ms - 30_000) / 1000.0 + 0.01
    st.boot_time(boot_ms, receipt)
    assert st.system_time(round((receipt - lag_s) * 1e6), boot_ms, receipt) is used
    assert (st.system_time_used, st.system_time_rejected) == ((1, 0) if used else (0, 1))
    m = _report(st, ev, boot_ms + 10, receipt + 0.01)
    delay = m.receipt_t_s - m.capture_t_s
    if used:
        assert delay == pytest.approx(lag_s, abs=1e-5)
    else:
        assert -1e-6 <= delay < 0.03


def _mission_current_frame(seq: int, total: int, state: int, mission_id: int, n: int) -> bytes:
    """MISSION_CURRENT as PX4 >= 1.14 sends it: with the 2023 extension fields (mission_id,
    fence_id, rally_points_id), which pymavlink's bundled dialect cannot encode."""
    payload = (
        seq.to_bytes(2, "little")
        + total.to_bytes(2, "little")
        + bytes([state, 0])
        + mission_id.to_bytes(4, "little")
        + bytes(8)
    )
    mid = MAVLINK_MSG_ID_MISSION_CURRENT
    hdr = bytes([0xFD, len(payload), 0, 0, n, 1, 1]) + mid.to_bytes(3, "little")
    extra = bytes([mav_common.MAVLink_mission_current_message.crc_extra])
    crc = crc16.mcrf4xx(extra, crc16.mcrf4xx(hdr[1:] + payload))
    return hdr + payload + crc.to_bytes(2, "little")


def _gps_fix(v: Any, fix: int) -> None:
    v.send(v.mav.gps_raw_int_encode(0, fix, 0, 0, 0, 80, 120, 0, 0, 12, 0, 1500, 2500, 0, 0))


async def test_home_position_before_a_3d_fix_is_not_the_home(env: Any) -> None:
    """PX4 sends HOME_POSITION 0.4 s after boot, before its fix (issue 31.3): not a home;
    the one after the fix is."""
    v = await env.vehicle(1)
    _gps_fix(v, 0)
    v.send(v.mav.home_position_encode(454671160, -737578370, 30340, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    await _settle()
    assert all(s.home is None for s in env.sink.statuses)
    _gps_fix(v, 3)
    v.send(v.mav.home_position_encode(454671160, -737578370, 32340, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    await _settle()
    home = env.sink.statuses[-1].home
    assert home is not None and home.alt_amsl_m == 32.34
    v.close()


async def test_home_position_and_mission_changes_reach_the_status(env: Any) -> None:
    v = await env.vehicle(1)
    _gps_fix(v, 3)
    v.send(v.mav.home_position_encode(454671160, -737578370, 32340, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    await _settle()
    home = env.sink.statuses[-1].home
    assert (home.lat_deg, home.lon_deg, home.alt_amsl_m) == (45.467116, -73.757837, 32.34)
    n = len(env.sink.statuses)
    v.send(v.mav.home_position_encode(454671160, -737578370, 32340, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    await _settle()
    assert len(env.sink.statuses) == n  # the same home: no status
    v.send_raw(_mission_current_frame(0, 4, 2, 0xA1B2C3D4, 7))
    await _settle()
    s = env.sink.statuses[-1]
    assert (s.mission_total, s.mission_id, s.mission_seq) == (4, 0xA1B2C3D4, 0)
    v.send_raw(_mission_current_frame(0, 4, 2, 0x0BADF00D, 8))  # same length, new mission
    await _settle()
    assert env.sink.statuses[-1].mission_id == 0x0BADF00D
    v.send_raw(_mission_current_frame(0, 0xFFFF, 0, 0, 9))  # PX4 with no mission
    await _settle()
    assert env.sink.statuses[-1].mission_id is None
    v.close()


def test_the_heading_of_global_position_int_is_in_the_status() -> None:
    """A fixed wing's take-off run is along the heading it armed with (GLOBAL_POSITION_INT
    hdg, cdeg; UINT16_MAX when the vehicle does not know it)."""
    st, ev = _clock_state()
    assert st.status(1000.0).heading_deg is None
    st.on_global_position((30_000, 473977000, 85456000, 488000, 0, 0, 0, 0, 4500), 1000.0, ev)
    assert st.status(1000.0).heading_deg == 45.0
    st.on_global_position((30_100, 473977000, 85456000, 488000, 0, 0, 0, 0, 65535), 1000.1, ev)
    assert st.status(1000.1).heading_deg is None


def test_clock_reboot_while_unheard_is_seen_though_its_clock_passed_the_old_one() -> None:
    """A power cycle while the link is down: the vehicle is heard again 60 s later, up for
    40 s, its clock past the 30 s of its last life. It booted while unheard: a reboot."""
    st, ev = _clock_state()
    _fly(st, ev, seconds=0.5, rate=1.0)  # up 30.5 s when last heard, at 1000.5
    _report(st, ev, 40_000, 1060.5)
    assert st.reboots == 1


def test_clock_silence_of_a_running_vehicle_is_no_reboot() -> None:
    """The link down for 60 s while the vehicle runs on (its clock at 0.8 x ours, a slow
    simulator): up 30 + 48 s, longer than the silence; no reboot."""
    st, ev = _clock_state()
    _fly(st, ev, seconds=0.5, rate=1.0)
    _report(st, ev, 30_500 + 48_000, 1060.5)
    assert st.reboots == 0


_MAV = mav_common.MAVLink(None, srcSystem=1, srcComponent=1)


def _frame(st: VehicleState, ev: _Events, t_s: float, status: int | None = None) -> None:
    """One datagram of the vehicle's stream: a HEARTBEAT with ``status`` (MAV_STATE), else
    a position report; sequence numbers as the sender counts them (mod 256)."""
    st.count_frame(_MAV.seq, t_s)
    _MAV.seq = (_MAV.seq + 1) % 256
    if status is not None:
        st.on_heartbeat(_MAV.heartbeat_encode(2, 12, 1, 0, status, 3), t_s, ev)


def test_a_px4_restarted_at_once_is_seen_by_its_boot_state() -> None:
    """A PX4 stopped 32 s after boot and started again at once (as measured on v1.15 SIH):
    its first HEARTBEATs, 0.6 s later, say MAV_STATE_UNINIT with the sequence back at 0; its
    first position comes 33.5 s into the new boot, after 34.1 s unheard. Its clock is past
    the old one and it was unheard for no longer than it has been up: only the boot state
    tells the two lives apart. One reboot, and the new clock is anchored afresh."""
    st, ev = _clock_state()
    _MAV.seq = 250
    for k in range(11):  # STANDBY, positions up to 32 s of boot time
        _frame(st, ev, 1000.0 + k * 0.1, status=3 if k % 5 == 0 else None)
        _report(st, ev, 31_000 + k * 100, 1000.0 + k * 0.1)
    assert st.reboots == 0
    _MAV.seq = 0  # the new process
    _frame(st, ev, 1001.6, status=0)
    assert st.reboots == 1
    _frame(st, ev, 1002.6, status=0)
    m = _report(st, ev, 33_500, 1001.0 + 34.1)
    assert st.reboots == 1  # the new clock is not a second reboot
    assert m.capture_t_s <= m.receipt_t_s
    _frame(st, ev, 1037.0, status=3)
    assert st.reboots == 1


def test_a_reboot_seen_by_the_clock_is_not_counted_again_by_the_boot_state() -> None:
    """An ArduCopter restarted: its SYSTEM_TIME (time_boot_ms back at 2.4 s) may come
    before its first HEARTBEAT (MAV_STATE_BOOT): one reboot."""
    st, ev = _clock_state()
    _frame(st, ev, 1000.0, status=3)
    _report(st, ev, 60_000, 1000.0)
    _report(st, ev, 2_400, 1003.0)
    assert st.reboots == 1
    _frame(st, ev, 1003.1, status=1)
    _frame(st, ev, 1004.1, status=3)
    assert st.reboots == 1


@pytest.mark.parametrize("dropped", [0, 1, 7])
def test_a_stream_with_a_wrap_a_drop_and_state_changes_is_no_reboot(dropped: int) -> None:
    """A running vehicle: its boot state (UNINIT, as PX4 at boot), then STANDBY, ACTIVE,
    CRITICAL, STANDBY again; the sequence wraps at 255 and ``dropped`` datagrams are lost on
    the way (one of them across the wrap). No reboot, and the loss is counted."""
    st, ev = _clock_state()
    _MAV.seq = 200
    states = [0, 0, 3, 4, 4, 5, 4, 3, 3, 2, 3]  # (2: CALIBRATING, on the ground)
    t = 1000.0
    for k in range(110):
        status = states[k // 10] if k % 10 == 0 else None
        if k == 55:  # around seq 255 -> 0
            _MAV.seq = (_MAV.seq + dropped) % 256
        _frame(st, ev, t, status=status)
        _report(st, ev, 30_000 + k * 20, t)
        t += 0.02
    assert st.reboots == 0
    assert st.lost == dropped


def test_the_status_gives_its_positions_capture_time_not_its_arrival() -> None:
    """Under load a backlog of positions is read seconds after the vehicle took them: a plan
    made from the last one starts at the time it was taken (the PX4 plane's loiter exit
    re-timed from a position 3 s old by its capture time, timed by its arrival: UAS_IN_CV
    19.4 m in the nuisance soak)."""
    st, ev = _clock_state()
    _fly(st, ev, seconds=1.0, rate=1.0)  # the clock anchored: boot 30 s at 1000 s
    st.on_global_position((31_100, 473977000, 85456000, 488000, 0, 0, 0, 0, 0), 1004.1, ev)
    s = st.status(1004.1)
    assert s.position_t_s is not None and abs(s.position_t_s - 1001.1) < 0.05
