"""The struct fast path of ``wire.Parser.feed_frames`` against pymavlink: the same fields on
random messages (MAVLink 2 with trailing-zero trimming, MAVLink 1), the same header, the same
rejections (bad CRC, garbage, truncation), and mixed datagrams with slow-path messages."""

from __future__ import annotations

import math
import os
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v10 import common as mav1
from pymavlink.dialects.v20 import common as mav2

from adapters.mavlink import wire

_INT = {
    "uint8_t": (0, 2**8 - 1),
    "int8_t": (-(2**7), 2**7 - 1),
    "uint16_t": (0, 2**16 - 1),
    "int16_t": (-(2**15), 2**15 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint64_t": (0, 2**64 - 1),
}


def _field(t: str) -> st.SearchStrategy[Any]:
    if t == "float":
        return st.floats(width=32, allow_nan=True, allow_infinity=True)
    lo, hi = _INT[t]
    # many zeros: MAVLink 2 trims trailing zero bytes, the padding must restore them
    return st.one_of(st.just(0), st.integers(lo, hi))


@st.composite
def _message(draw: st.DrawFn) -> tuple[int, list[Any]]:
    mid = draw(st.sampled_from(wire.FAST_IDS))
    cls = mav2.mavlink_map[mid]
    return mid, [draw(_field(t)) for t in cls.fieldtypes]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return bool(a == b)


def _check_same(fast: list[wire.Frame], slow: list[wire.Frame]) -> None:
    assert len(fast) == len(slow)
    for f, s in zip(fast, slow, strict=True):
        assert f[:4] == s[:4]
        for name in s.msg.get_fieldnames():
            assert _same(getattr(f.msg, name), getattr(s.msg, name)), name


@settings(max_examples=300, deadline=None)
@given(_message(), st.integers(1, 255), st.integers(0, 255), st.integers(0, 255))
def test_fast_path_equals_pymavlink_v2(
    msg: tuple[int, list[Any]], sys_id: int, comp_id: int, seq: int
) -> None:
    mid, values = msg
    enc = mav2.MAVLink(None, srcSystem=sys_id, srcComponent=comp_id)
    enc.seq = seq
    frame = bytes(mav2.mavlink_map[mid](*values).pack(enc))
    assert frame[0] == 0xFD
    fast = wire.Parser()
    got = fast.feed_frames(frame)
    assert type(got[0].msg) is not mav2.mavlink_map[mid]  # really the fast path
    _check_same(got, wire.Parser(fast=False).frames(frame, datagram=True))
    assert fast.counters.frames == 1 and fast.counters.bad_frames == 0


@settings(max_examples=150, deadline=None)
@given(_message(), st.integers(1, 255))
def test_fast_path_equals_pymavlink_v1(msg: tuple[int, list[Any]], sys_id: int) -> None:
    mid, values = msg
    cls1 = mav1.mavlink_map[mid]
    base = dict(zip(mav2.mavlink_map[mid].fieldnames, values, strict=True))
    enc = mav1.MAVLink(None, srcSystem=sys_id, srcComponent=1)
    frame = bytes(cls1(*[base[n] for n in cls1.fieldnames]).pack(enc))
    assert frame[0] == 0xFE
    _check_same(
        wire.Parser().feed_frames(frame), wire.Parser(fast=False).frames(frame, datagram=True)
    )


def _gpi(enc: Any, boot_ms: int = 1000) -> bytes:
    return bytes(
        enc.global_position_int_encode(
            boot_ms, 473977418, 85455939, 500000, 10000, 1, -2, 3, 0
        ).pack(enc)
    )


def test_bad_crc_rejected_and_counted_like_pymavlink() -> None:
    enc = mav2.MAVLink(None, srcSystem=3, srcComponent=1)
    good = _gpi(enc)
    for pos in (-1, -2, 12, 5):  # CRC bytes, payload, sysid
        bad = bytearray(good)
        bad[pos] ^= 0x5A
        fast, slow = wire.Parser(), wire.Parser(fast=False)
        assert fast.feed_frames(bytes(bad)) == []
        assert slow.frames(bytes(bad), datagram=True) == []
        assert fast.counters.bad_crc == slow.counters.bad_crc == 1, pos
        # the parser keeps working afterwards
        assert len(fast.feed_frames(good)) == 1


def test_mixed_datagram_fast_slow_garbage_truncated() -> None:
    enc = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    parts = [
        _gpi(enc, 1),
        bytes(enc.statustext_encode(4, b"GPS jamming").pack(enc)),
        bytes(enc.heartbeat_encode(2, 12, 129, 4 << 16, 4, 3).pack(enc)),
        bytes(enc.command_ack_encode(176, 0).pack(enc)),
        _gpi(enc, 2),
    ]
    data = b"".join(parts)
    fast, slow = wire.Parser(), wire.Parser(fast=False)
    f = fast.feed_frames(data)
    _check_same(f, slow.frames(data, datagram=True))
    assert [x.msg_id for x in f] == [33, 253, 0, 77, 33]
    # garbage then a frame; a frame cut at the end of the datagram
    for tail in (b"\x00\x01garbage" + parts[0], parts[0] + parts[4][:9], parts[0] + b"\xfd"):
        fast, slow = wire.Parser(), wire.Parser(fast=False)
        a, b = fast.feed_frames(tail), slow.frames(tail, datagram=True)
        _check_same(a, b)
        ca, cb = fast.counters, slow.counters
        assert (ca.garbage, ca.truncated, ca.bad_crc) == (cb.garbage, cb.truncated, cb.bad_crc)
        assert ca.bad_frames >= 1


def test_signed_frames_go_through_pymavlink() -> None:
    key = bytes(range(32))
    enc = wire.Encoder(1, 1, key=key)
    frame = enc.raw("global_position_int", 5, 1, 2, 3, 4, 5, 6, 7, 8)
    assert frame[2] & 1
    [fr] = wire.Parser().feed_frames(frame)
    assert type(fr.msg) is mav2.MAVLink_global_position_int_message
    assert wire.Parser(key=key).feed_frames(frame)[0].msg.lat == 1
    assert wire.Parser(key=bytes(32)).feed_frames(frame) == []


@pytest.mark.parametrize("mid", wire.FAST_IDS)
def test_every_fast_type_matches_dialect_size(mid: int) -> None:
    assert wire.FAST_TYPES[mid].size == mav2.mavlink_map[mid].unpacker.size


# --- odd single datagrams: the fast decoder decides and counts as pymavlink does -----------
_GPI_FIELDS = mav2.mavlink_map[wire.GLOBAL_POSITION_INT].ordered_fieldnames


def _with_crc(body: bytes, extra: int) -> bytes:
    """A MAVLink 2 frame from everything but its CRC (the CRC computed here with pymavlink's
    own x25crc)."""
    from pymavlink.generator.mavcrc import x25crc

    crc = x25crc(body[1:])
    crc.accumulate(bytes([extra]))
    return body + int(crc.crc).to_bytes(2, "little")


def _parsed(data: bytes, *, fast: bool) -> tuple[list[tuple[Any, ...]], dict[str, Any]]:
    counters = wire.ParseCounters()
    frames = wire.Parser(counters, fast=fast).feed_frames(data)
    got = [(*f[:4], tuple(getattr(f.msg, n) for n in _GPI_FIELDS)) for f in frames]
    return got, {k: getattr(counters, k) for k in counters.__dataclass_fields__}


def test_odd_position_datagrams_decode_and_count_as_pymavlink() -> None:
    """Cut, padded, doubled, corrupted, MAVLink 1, signed and other-type datagrams: the fast
    decoder gives pymavlink's frames and rejections, and a longer payload (a newer dialect) is
    cut to the fields we know."""
    enc = mav2.MAVLink(None, srcSystem=3, srcComponent=1)
    good = _gpi(enc)
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0x01
    v1 = bytes(
        mav1.MAVLink_global_position_int_message(1, 2, 3, 4, 5, 6, 7, 8, 9).pack(
            mav1.MAVLink(None, srcSystem=3, srcComponent=1)
        )
    )
    signed = wire.Encoder(3, 1, key=bytes(range(32))).raw(
        "global_position_int", 5, 1, 2, 3, 4, 5, 6, 7, 8
    )
    for data in (
        b"",
        good,
        good[:11],
        good[:-1],  # cut short
        good + b"\x00",  # a trailing byte
        good + _gpi(enc, 2),  # two frames in one datagram
        signed + good,  # a signed frame, then a plain one
        bytes(bad_crc),
        bytes(bad_crc) + good,
        v1,
        signed,
    ):
        assert _parsed(data, fast=True) == _parsed(data, fast=False), data.hex()
    extra = mav2.MAVLink_global_position_int_message.crc_extra
    payload = mav2.MAVLink_global_position_int_message.unpacker.pack(
        1000, 473977418, 85455939, 500000, 10000, 1, -2, 3, 7
    )
    longer = _with_crc(bytes([0xFD, 30, 0, 0, 9, 3, 1, 33, 0, 0]) + payload + b"\x01\x02", extra)
    [ref] = wire.Parser().feed_frames(longer)
    assert ref[1:4] == (3, 1, 9)
    assert tuple(ref.msg) == (1000, 473977418, 85455939, 500000, 10000, 1, -2, 3, 7)


async def test_hub_with_the_fast_decoder_equals_pymavlink_for_everything() -> None:
    """The same datagrams through a hub with the fast decoder and one with pymavlink for
    everything (``fast_decode`` false): the same measurements, link statistics (loss,
    duplicates, reboots), counters and vehicles."""
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from gcs_utm.clock import ManualClock

    from .conftest import Sink

    a, b = ("10.0.0.1", 14550), ("10.0.0.2", 14550)
    e1 = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    e2 = mav2.MAVLink(None, srcSystem=2, srcComponent=1)  # another vehicle, another address
    hb = bytes(e1.heartbeat_encode(2, 12, 129, 4 << 16, 4, 3).pack(e1))
    e1.seq = 1

    def gpi(enc: Any, boot_ms: int) -> bytes:
        frame = _gpi(enc, boot_ms)
        enc.seq = (enc.seq + 1) % 256  # pack() alone does not count
        return frame

    seqs: list[tuple[bytes, tuple[str, int]]] = [(hb, a)]
    for i in range(40):
        boot = 5000 + 100 * i if i < 30 else 100 * (i - 30)  # a reboot at i = 30
        if i in (7, 8):
            e1.seq = (e1.seq + 3) % 256  # 3 frames lost before each
        frame = gpi(e1, boot)
        seqs.append((frame, a))
        if i == 12:
            seqs.append((frame, a))  # duplicated datagram
        if i == 20:
            bad = bytearray(frame)
            bad[-1] ^= 0xFF
            seqs.append((bytes(bad), a))
        seqs.append((gpi(e2, 9000 + 100 * i), b))
    seqs.append((gpi(e1, 99999) + gpi(e1, 100000), a))  # two frames, one datagram
    no_fix = bytes(e1.global_position_int_encode(100100, 0, 0, 0, 0, 0, 0, 0, 0).pack(e1))
    e1.seq += 1
    seqs.append((no_fix, a))

    async def run(fast: bool) -> tuple[Sink, MavlinkHub]:
        sink = Sink()
        clock = ManualClock(1_700_000_000.0)
        hub = MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",), fast_decode=fast), clock, sink)
        await hub.start()
        link = next(iter(hub._links.values()))
        for data, addr in seqs:
            clock.advance(0.01)
            hub._on_chunk(link, data, addr)
        await hub.close()
        return sink, hub

    fast, hub_fast = await run(True)
    slow, hub_slow = await run(False)
    # the duplicated datagram is a measurement too (tracking drops it as a duplicate)
    assert len(fast.measurements) == len(slow.measurements) == 2 * 40 + 1 + 2
    assert fast.measurements == slow.measurements
    assert hub_fast.counters.snapshot() == hub_slow.counters.snapshot()
    assert hub_fast.counters.bad_crc == 1 and hub_fast.counters.frames == 1 + 80 + 1 + 2 + 1
    assert len(fast.vehicles) == len(slow.vehicles) == 1
    for key in hub_slow._states:
        sf, ss = hub_fast._states[key], hub_slow._states[key]
        got = (sf.received, sf.lost, sf.duplicates, sf.reboots, sf.offset_s, sf.tag)
        assert got == (ss.received, ss.lost, ss.duplicates, ss.reboots, ss.offset_s, ss.tag)
    [st1] = [s for k, s in hub_fast._states.items() if k[1] == a]
    assert (st1.lost, st1.duplicates, st1.reboots) == (6, 1, 1)
