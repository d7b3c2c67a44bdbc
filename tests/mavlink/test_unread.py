"""Messages the hub never reads are framed and checked, not decoded.

A PX4 SITL's GCS link streams seven messages at 50 Hz (ATTITUDE_QUATERNION, ATTITUDE_TARGET,
LOCAL_POSITION_NED, POSITION_TARGET_LOCAL_NED, SERVO_OUTPUT_RAW, ...: 370 datagrams/s, 1,850/s
per vehicle at a speed factor of 5), of which the hub reads none. Decoded by pymavlink they
took most of the parser's time (27.6 against 2.5 us a datagram on a captured PX4 stream):
on a loaded machine the reader fell seconds behind, its receive buffer overflowed and dropped
COMMAND_ACKs and positions (docs/autopilots.md, "PX4 SITL under load")."""

from __future__ import annotations

import os
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav2

from adapters.mavlink import MavlinkConfig, MavlinkHub, wire
from gcs_utm.clock import ManualClock

from .conftest import Sink


def _attitude_q(enc: Any, boot_ms: int) -> bytes:
    return bytes(enc.attitude_quaternion_encode(boot_ms, 1.0, 0.0, 0.0, 0.0, 0, 0, 0).pack(enc))


def _gpi(enc: Any, boot_ms: int) -> bytes:
    msg = enc.global_position_int_encode(boot_ms, 473977418, 85455939, 500000, 10000, 1, 2, 3, 0)
    return bytes(msg.pack(enc))


class _Spy:
    """Counts the frames handed to pymavlink."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls = 0
        real = wire.Parser.feed

        def feed(parser: wire.Parser, data: bytes, *, datagram: bool) -> list[Any]:
            self.calls += 1
            return real(parser, data, datagram=datagram)

        monkeypatch.setattr(wire.Parser, "feed", feed)


def test_skipped_ids_are_framed_and_checked_not_decoded(monkeypatch: pytest.MonkeyPatch) -> None:
    spy = _Spy(monkeypatch)
    enc = mav2.MAVLink(None, srcSystem=2, srcComponent=1)
    enc.seq = 41
    data = _attitude_q(enc, 10) + _gpi(enc, 10)
    parser = wire.Parser(skip=wire.unread_ids({wire.GLOBAL_POSITION_INT}))
    skipped, gpi = parser.feed_frames(data)
    assert skipped == (mav2.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, 2, 1, 41, None)
    assert gpi[:4] == (wire.GLOBAL_POSITION_INT, 2, 1, 41) and gpi.msg.lat == 473977418
    assert spy.calls == 0 and parser.counters.frames == 2
    # a skipped frame with a bad CRC is rejected and counted as pymavlink counts it
    bad = bytearray(_attitude_q(enc, 20))
    bad[-1] ^= 0x5A
    assert parser.feed_frames(bytes(bad)) == []
    assert parser.counters.bad_crc == 1 and spy.calls == 1


async def test_hub_decodes_only_what_it_reads(monkeypatch: pytest.MonkeyPatch) -> None:
    enc = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    clock = ManualClock(1_700_000_000.0)
    hub = MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",)), clock, Sink())
    await hub.start()
    try:
        spy = _Spy(monkeypatch)
        link = next(iter(hub._links.values()))
        addr = ("127.0.0.1", 18570)
        for i in range(50):  # one second of a PX4 SITL's attitude stream, positions between
            clock.advance(0.02)
            hub._on_chunk(link, _attitude_q(enc, 20 * i), addr)
            hub._on_chunk(link, _gpi(enc, 20 * i), addr)
        hub._on_chunk(link, bytes(enc.command_ack_encode(176, 0).pack(enc)), addr)
        assert spy.calls == 1  # the COMMAND_ACK (a transfer reads it), nothing else
        c = hub.counters
        assert c.frames == 101 and c.bad_crc == c.garbage == c.unknown_msg == c.truncated == 0
        [st] = hub._states.values()
        assert (st.received, st.lost) == (101, 0)  # link statistics count every frame
    finally:
        await hub.close()


def test_a_signed_link_decodes_everything() -> None:
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), signing_keys={"7": "11" * 32})
    hub = MavlinkHub(cfg, ManualClock(1_700_000_000.0), Sink())
    assert hub._unread == frozenset()
