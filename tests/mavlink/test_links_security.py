"""Incoming MAVLink 2 signatures are verified for vehicles whose key is known (issue 21 item
4): a good signature passes, a wrong key, an unsigned frame and a replayed timestamp are
dropped and counted by cause; end to end against a ``sitl`` vehicle that signs with a key the
ground does not hold."""

from __future__ import annotations

import asyncio
import os
import time
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v10 import common as mav1
from pymavlink.dialects.v20 import common as mav

import sitl
from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.wire import signing_timestamp
from gcs_utm.clock import ManualClock, ScaledClock
from gcs_utm.model import SysId, ThreatKind
from tests.mavlink.conftest import Sink
from tests.mavlink.test_sitl import _spec
from tests.mavlink.test_sitl_signing import FLYING, KEY, WRONG

T0 = 1_700_000_000.0


def _signer(key_hex: str, sys_id: int = 1, *, stamp_s: float | None = None) -> Any:
    enc = mav.MAVLink(None, srcSystem=sys_id, srcComponent=1)
    s = enc.signing
    s.secret_key = bytes.fromhex(key_hex)
    s.sign_outgoing = True
    s.link_id = 0
    s.timestamp = signing_timestamp(time.time() if stamp_s is None else stamp_s)
    return enc


def _hb(enc: Any) -> bytes:
    return bytes(enc.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(enc))


def _gpi(enc: Any, boot_ms: int = 1000) -> bytes:
    msg = enc.global_position_int_encode(boot_ms, 473977418, 85455939, 500000, 20000, 0, 0, 0, 0)
    return bytes(msg.pack(enc))


async def _hub(**kw: Any) -> tuple[MavlinkHub, Any, Sink]:
    sink = Sink()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), health_period_s=3600.0, **kw)
    hub = MavlinkHub(cfg, ManualClock(T0), sink)
    await hub.start()
    return hub, next(iter(hub._links.values())), sink


async def test_frames_of_a_keyed_vehicle_are_verified_and_bad_ones_counted_by_cause() -> None:
    hub, link, sink = await _hub(signing_keys={"1": KEY})
    a = ("10.0.0.1", 14550)
    try:
        good = _signer(KEY)
        hub._on_chunk(link, _hb(good), a)
        hub._on_chunk(link, _gpi(good), a)
        assert [v.key.sys_id for v in sink.vehicles] == [1] and len(sink.measurements) == 1
        c = hub.counters
        # a wrong key, from the vehicle's own address: dropped, counted, nothing used
        wrong = _signer(WRONG)
        for _ in range(5):
            hub._on_chunk(link, _gpi(wrong), a)
        assert c.bad_signature == 5 and len(sink.measurements) == 1
        # unsigned MAVLink 2 (fast path and fused position path) and MAVLink 1
        plain = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        hub._on_chunk(link, _gpi(plain), a)
        hub._on_chunk(link, _hb(plain), a)
        v1 = mav1.MAVLink(None, srcSystem=1, srcComponent=1)
        hub._on_chunk(link, bytes(v1.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(v1)), a)
        assert c.unsigned == 3
        # RADIO_STATUS may come unsigned (radios inject it)
        hub._on_chunk(link, bytes(plain.radio_status_encode(1, 2, 3, 4, 5, 6, 7).pack(plain)), a)
        assert c.unsigned == 3
        # a replay: a frame recorded earlier, sent again
        frame = _gpi(good)
        hub._on_chunk(link, frame, a)
        hub._on_chunk(link, frame, a)
        assert c.replayed == 1 and len(sink.measurements) == 2
        # a new stream (another link id) that starts more than a minute in the past
        old = _signer(KEY, stamp_s=time.time() - 120.0)
        old.signing.link_id = 7
        hub._on_chunk(link, _gpi(old), a)
        assert c.replayed == 2
        # nothing is claimed or reported: forged frames never reach the binding
        assert c.sysid_claims == 0 and not sink.hazards
        # unkeyed system ids are not checked
        other = mav.MAVLink(None, srcSystem=2, srcComponent=1)
        hub._on_chunk(link, _hb(other), ("10.0.0.2", 14550))
        assert {v.key.sys_id for v in sink.vehicles} == {1, 2}
        assert link.counters.bad_frames == 5  # wrong signatures are bad frames of the link
        assert hub._verify is not None and hub._verify.counters.verified == 3
    finally:
        await hub.close()


async def test_a_spoofer_without_the_key_cannot_claim_a_keyed_vehicle() -> None:
    hub, link, sink = await _hub(signing_keys={"1": KEY})
    try:
        spoof = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        for i in range(50):
            hub._on_chunk(link, _hb(spoof), ("10.6.6.6", 1000 + i))
        good = _signer(KEY)
        hub._on_chunk(link, _hb(good), ("10.0.0.1", 14550))
        assert hub.state(SysId(1)).key.address == "10.0.0.1:14550"
        assert hub.counters.unsigned == 50 and hub.counters.sysid_claims == 0
        claims = (ThreatKind.SYSID_CONFLICT, ThreatKind.SPOOFING_ATTACK)
        assert not [h for h in sink.hazards if h.kind in claims]
        # a signed vehicle may move to another host after silence (cellular re-attach): its
        # signature says who it is
        hub.clock.advance(5.0)
        hub._on_chunk(link, _hb(_signer(KEY)), ("10.0.0.99", 14550))
        assert hub.state(SysId(1)).key.address == "10.0.0.99:14550"
        assert hub.counters.address_changes == 1 and hub.counters.sysid_claims == 0
    finally:
        await hub.close()


@pytest.mark.network
@pytest.mark.timeout(60)
async def test_sitl_vehicle_signing_with_another_key_is_dropped() -> None:
    sim = sitl.SimTime(4.0)
    clock = ScaledClock(4.0, start_utc_s=sim.start_utc_s, start_mono_s=sim.start_mono_s)
    for ground_key, accepted in ((WRONG, False), (KEY, True)):
        sink = Sink()
        cfg = MavlinkConfig(
            links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2, signing_keys={"1": ground_key}
        )
        async with MavlinkHub(cfg, clock, sink) as hub:
            port = hub.local_port(next(iter(hub._links)))
            async with sitl.Fleet([_spec(gcs_port=port, **FLYING)], sim):
                end = time.monotonic() + 5.0
                while time.monotonic() < end and not (
                    len(sink.measurements) >= 3 or hub.counters.bad_signature >= 20
                ):
                    await asyncio.sleep(0.05)
        if accepted:
            assert len(sink.measurements) >= 3 and hub.counters.bad_signature == 0
        else:
            assert hub.counters.bad_signature >= 20
            assert not sink.measurements and not sink.vehicles and not sink.statuses
