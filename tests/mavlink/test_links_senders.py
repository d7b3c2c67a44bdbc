"""Per-sender state of the hub is bounded (issue 21 item 3): parsers per address and vehicle
states are capped and forgotten when idle, on an injected clock, and counted; a system id is
bound to where it was first heard (item 4); repeated warnings are rate-limited (item 5)."""

from __future__ import annotations

import asyncio
import logging
import os
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.senders import idle_keys, over_cap_keys
from gcs_utm.clock import ManualClock
from gcs_utm.model import SysId, ThreatKind
from gcs_utm.ratelog import RateLimitedLog
from tests.mavlink.conftest import Sink

T0 = 1_700_000_000.0


def _enc(sys_id: int, comp_id: int = 1) -> Any:
    return mav.MAVLink(None, srcSystem=sys_id, srcComponent=comp_id)


def _hb(enc: Any, autopilot: int = 12) -> bytes:
    return bytes(enc.heartbeat_encode(2, autopilot, 129, 0, 4, 3).pack(enc))


def _gpi(enc: Any, boot_ms: int) -> bytes:
    return bytes(
        enc.global_position_int_encode(
            boot_ms, 473977418, 85455939, 500000, 20000, 0, 0, 0, 0
        ).pack(enc)
    )


async def _hub(**kw: Any) -> tuple[MavlinkHub, Any, ManualClock, Sink]:
    clock = ManualClock(T0)
    sink = Sink()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), health_period_s=3600.0, **kw)
    hub = MavlinkHub(cfg, clock, sink)
    await hub.start()
    return hub, next(iter(hub._links.values())), clock, sink


def test_idle_and_cap_selection() -> None:
    last = {f"k{i}": float(i) for i in range(16)}
    assert idle_keys(last, 20.0, 10.0) == [f"k{i}" for i in range(11)]
    assert idle_keys(last, 20.0, 10.0, keep=lambda k: k == "k3") == [
        f"k{i}" for i in range(11) if i != 3
    ]
    assert over_cap_keys(last, 17) == []
    # full: the oldest eighth goes (16 - 16 // 8 = 14 remain)
    assert over_cap_keys(last, 16) == ["k0", "k1"]
    assert over_cap_keys(last, 16, keep=lambda k: k == "k0") == ["k1", "k2"]
    assert over_cap_keys({"a": 1.0}, 1) == ["a"]


async def test_senders_capped_then_forgotten_when_idle() -> None:
    hub, link, clock, _sink = await _hub(max_senders=16, max_vehicles=32, sender_idle_s=30.0)
    try:
        for i in range(200):  # 200 spoofed identities, each from its own port
            clock.advance(0.01)
            hub._on_chunk(link, _hb(_enc(i % 250 + 1, i % 7 + 1)), ("10.0.0.9", 40000 + i))
        assert len(link.parsers) <= 16 and len(link.seen) <= 16
        assert len(hub._states) <= 32
        c = hub.counters
        assert c.senders_evicted >= 200 - 16 and c.vehicles_evicted >= 200 - 32
        # the most recent ones are kept
        assert ("10.0.0.9", 40199) in link.parsers
        assert ("10.0.0.9", 40000) not in link.parsers
        # idle: nothing is left after sender_idle_s of silence
        clock.advance(29.0)
        hub.evict_idle()
        assert hub._states and link.parsers
        clock.advance(1.1)
        hub.evict_idle()
        assert not hub._states and not link.parsers and not link.peers and not link.seen
        assert not hub._addr and not hub._by_sysid
        assert c.senders_evicted + len(link.parsers) >= 200
        assert hub.links()[0].senders == 0
    finally:
        await hub.close()


async def test_a_vehicle_in_a_transfer_is_not_evicted_and_a_forgotten_one_comes_back() -> None:
    hub, link, clock, sink = await _hub(max_vehicles=4, sender_idle_s=10.0)
    try:
        e = _enc(3)
        hub._on_chunk(link, _hb(e), ("10.0.0.3", 14550))
        st = hub.state(SysId(3))
        async with hub.transfers.exchange(st):
            clock.advance(20.0)
            hub.evict_idle()
            assert hub.state(SysId(3)) is st  # busy: kept
            for i in range(10):
                hub._on_chunk(link, _hb(_enc(10 + i)), ("10.0.0.4", 15000 + i))
            assert hub.state(SysId(3)) is st and len(hub._states) <= 4
        clock.advance(20.0)
        hub.evict_idle()
        assert not hub._states and hub.counters.vehicles_evicted >= 11
        hub._on_chunk(link, _hb(e), ("10.0.0.3", 14550))
        assert hub.state(SysId(3)) is not st  # discovered again
        assert [v.key.sys_id for v in sink.vehicles].count(3) == 2
    finally:
        await hub.close()


async def test_sysid_zero_is_never_a_vehicle() -> None:
    hub, link, _clock, sink = await _hub()
    try:
        e0 = _enc(0)
        hub._on_chunk(link, _hb(e0), ("10.0.0.1", 1))
        hub._on_chunk(link, _gpi(e0, 1000), ("10.0.0.1", 1))
        assert not hub._states and not sink.vehicles and not sink.measurements
        assert hub.counters.sysid_zero == 2
    finally:
        await hub.close()


async def test_a_second_sender_claiming_a_bound_sysid_is_dropped_and_reported() -> None:
    hub, link, clock, sink = await _hub(warn_interval_s=10.0, address_move_s=3.0)
    try:
        owner, spoof = _enc(1), _enc(1)
        a, b = ("10.0.0.1", 14550), ("10.0.0.66", 14550)
        hub._on_chunk(link, _hb(owner), a)
        for i in range(100):
            clock.advance(0.01)
            hub._on_chunk(link, _gpi(owner, 1000 + 10 * i), a)
            hub._on_chunk(link, _hb(spoof), (b[0], b[1] + i))  # from 100 ports
            hub._on_chunk(link, _gpi(spoof, 5000 + 10 * i), (b[0], b[1] + i))
        assert hub.counters.sysid_claims == 200
        assert [v.key.address for v in hub.vehicles()] == ["10.0.0.1:14550"]
        assert hub.state(SysId(1)).key.address == "10.0.0.1:14550"
        assert {m.vehicle for m in sink.measurements} == {"10.0.0.1:14550"}
        # a link-level claim, not the vehicle's GNSS being spoofed (which EM suspends for)
        assert not [h for h in sink.hazards if h.kind is ThreatKind.SPOOFING_ATTACK]
        claims = [h for h in sink.hazards if h.kind is ThreatKind.SYSID_CONFLICT]
        assert len(claims) == 1 and claims[0].sys_id == 1  # one per interval
        assert "10.0.0.66" in claims[0].message and "10.0.0.1:14550" in claims[0].message
        clock.advance(10.0)  # the next interval: reported again
        hub._on_chunk(link, _hb(owner), a)
        hub._on_chunk(link, _hb(spoof), b)
        assert len([h for h in sink.hazards if h.kind is ThreatKind.SYSID_CONFLICT]) == 2
        # a claim over another link is refused even after silence (no move across links)
        other = await hub.add_link("udpin:127.0.0.1:0")
        clock.advance(5.0)
        hub._on_chunk(hub._links[other], _hb(spoof), ("127.0.0.1", 9))
        assert hub.counters.sysid_claims == 202 and hub.counters.address_changes == 0
        # the same link after address_move_s of silence, from another host: still a claim
        hub._on_chunk(link, _hb(spoof), b)
        assert hub.counters.sysid_claims == 203 and hub.counters.address_changes == 0
        # from the same host, another port (NAT rebinding, a restarted SITL): it moved
        hub._on_chunk(link, _hb(owner), ("10.0.0.1", 14551))
        assert hub.counters.address_changes == 1
        assert hub.state(SysId(1)).key.address == "10.0.0.1:14551"
    finally:
        await hub.close()


async def test_backwards_time_boot_ms_warns_once_per_interval(
    caplog: pytest.LogCaptureFixture,
) -> None:
    hub, link, clock, _sink = await _hub(warn_interval_s=10.0)
    try:
        e = _enc(4)
        addr = ("10.0.0.4", 14550)
        hub._on_chunk(link, _hb(e), addr)
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            for i in range(2000):  # time_boot_ms 100 s, 0, 100 s, 0, ...: 1,000 "reboots"
                clock.advance(0.001)
                hub._on_chunk(link, _gpi(e, 0 if i % 2 else 100_000), addr)
            reboots = [r for r in caplog.records if "rebooted" in r.getMessage()]
            assert hub.state(SysId(4)).reboots == 1000
            assert len(reboots) == 1
            clock.advance(10.0)
            hub._on_chunk(link, _gpi(e, 100_000), addr)
            hub._on_chunk(link, _gpi(e, 0), addr)
            reboots = [r for r in caplog.records if "rebooted" in r.getMessage()]
            assert len(reboots) == 2 and "999 more since the last line" in reboots[1].getMessage()
    finally:
        await hub.close()


def test_rate_limited_log_counts_what_it_holds_back(caplog: pytest.LogCaptureFixture) -> None:
    t = [0.0]
    log = logging.getLogger("test.ratelog")
    rl = RateLimitedLog(log, 5.0, now=lambda: t[0], max_causes=2)
    with caplog.at_level(logging.INFO, logger="test.ratelog"):
        assert rl.warning("a", "a %d", 1)
        assert not rl.warning("a", "a %d", 2)
        assert not rl.warning("a", "a %d", 3)
        assert rl.info("b", "b")
        t[0] = 5.0
        assert rl.flush() == 1  # a: the last held line, with the count of the others
        assert not rl.warning("a", "a %d", 4)  # the flushed line started an interval
        t[0] = 10.0
        assert rl.warning("a", "a %d", 5)
        assert rl.held_total == 3
        assert not rl.warning("a", "a %d", 6)
        assert rl.warning("c", "c")  # a third cause: the oldest (b) is forgotten
        assert set(rl._causes) <= {"a", "c"} and len(rl._causes) == 2
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "a 1",
        "b",
        "a 3 (1 more since the last line)",
        "a 5 (1 more since the last line)",
        "c",
    ]
    with pytest.raises(ValueError, match="interval_s"):
        RateLimitedLog(log, -1.0)


async def test_config_rejects_inverted_backoff_and_bad_links() -> None:
    from gcs_utm.config import ConfigError, build

    with pytest.raises(ConfigError, match=r"reconnect_min_s \(5.0\) must not exceed"):
        build(
            MavlinkConfig,
            {"reconnect_min_s": 5.0, "reconnect_max_s": 1.0},
            source="x.toml",
            section="mavlink",
        )
    with pytest.raises(ConfigError, match=r"x\.toml: mavlink: links: connection string"):
        build(MavlinkConfig, {"links": ["tcp:nohost"]}, source="x.toml", section="mavlink")
    with pytest.raises(ConfigError, match="32 bytes"):
        build(MavlinkConfig, {"signing_keys": {"1": "ab"}}, source="x.toml", section="mavlink")
    await asyncio.sleep(0)


async def test_refused_and_forgotten_senders_are_summed_up_once_a_minute(
    caplog: pytest.LogCaptureFixture,
) -> None:
    hub, link, clock, _sink = await _hub(sender_idle_s=30.0)
    try:
        hub._on_chunk(link, _hb(_enc(1)), ("10.0.0.1", 1))
        with caplog.at_level(logging.INFO):
            for i in range(50):
                hub._on_chunk(link, _hb(_enc(1)), ("10.6.6.6", 100 + i))  # claims
                hub._on_chunk(link, _hb(_enc(0)), ("10.6.6.7", 100 + i))  # sysid 0
            hub.evict_idle()
            assert not [r for r in caplog.records if "in the last" in r.getMessage()]
            clock.advance(61.0)
            hub.evict_idle()
            hub.evict_idle()  # nothing new, and within the minute: no second line
            [line] = [r for r in caplog.records if "in the last" in r.getMessage()]
            assert line.levelno == logging.WARNING
            text = line.getMessage()
            assert "sysid_claims 50" in text and "sysid_zero 50" in text
            assert "senders_evicted 101" in text and "vehicles_evicted 1" in text
    finally:
        await hub.close()
