"""The only module that touches pymavlink (untyped): sans-IO parsing and encoding behind small
typed helpers.

- :class:`Parser` turns received bytes into decoded messages and counts what it rejects (bad
  CRC, garbage, unknown message ids, truncated frames, bad signatures). It never raises.
  For datagram links each datagram is parsed on its own (MAVLink never splits a frame across
  UDP datagrams), so a truncated frame cannot swallow the next datagram.
- :class:`Encoder` packs outgoing messages with our system/component id and a per-encoder
  sequence number, MAVLink 2, optionally signed (MAVLink 2 signing, SHA-256, 48-bit
  timestamp in 10 µs units since 2015-01-01).

Decoded messages are pymavlink objects (typed ``Any`` here): attribute access by MAVLink field
name; :func:`msg_id`, :func:`src` give typed header access.

One receive decoder (:meth:`Parser.feed_frames`, datagram links): the hot telemetry messages
in :data:`FAST_TYPES` (HEARTBEAT, SYS_STATUS, SYSTEM_TIME, GPS_RAW_INT, ATTITUDE,
GLOBAL_POSITION_INT, VFR_HUD, EXTENDED_SYS_STATE) are framed and checked here (MAVLink 2
header 0xFD len incompat compat seq sysid compid msgid[3]; MAVLink 1 0xFE len seq sysid compid
msgid; X.25 CRC-16/MCRF4XX over header+payload then CRC_EXTRA, via fastcrc) and unpacked with
``struct`` into named tuples with pymavlink's field names, after padding the payload that
MAVLink 2 trims of trailing zeros. Each type's layout (struct format, field names in wire
order, payload size, CRC_EXTRA) is taken from pymavlink's message class in the dialect, so it
is defined once. The ids a parser is told to ``skip`` (those its reader never uses) are
framed and checked the same way but not unpacked (``msg`` None). Anything else -- other
messages, signed frames, a bad CRC, garbage, a frame
cut short -- goes to pymavlink from that byte on (the fallback), so rejects are classified and
counted as pymavlink classifies them.
"""

from __future__ import annotations

import struct
import time
from collections import namedtuple
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import partial
from typing import Any, NamedTuple

from fastcrc import crc16
from pymavlink.dialects.v20 import common as mav

MavMsg = Any
"""A decoded pymavlink message (untyped library object)."""

# Message ids we use (from the common dialect, named here so the rest is pymavlink-free).
HEARTBEAT = mav.MAVLINK_MSG_ID_HEARTBEAT
SYS_STATUS = mav.MAVLINK_MSG_ID_SYS_STATUS
SYSTEM_TIME = mav.MAVLINK_MSG_ID_SYSTEM_TIME
GPS_RAW_INT = mav.MAVLINK_MSG_ID_GPS_RAW_INT
GLOBAL_POSITION_INT = mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
MISSION_ITEM = mav.MAVLINK_MSG_ID_MISSION_ITEM
MISSION_REQUEST = mav.MAVLINK_MSG_ID_MISSION_REQUEST
MISSION_CURRENT = mav.MAVLINK_MSG_ID_MISSION_CURRENT
MISSION_COUNT = mav.MAVLINK_MSG_ID_MISSION_COUNT
MISSION_ACK = mav.MAVLINK_MSG_ID_MISSION_ACK
MISSION_REQUEST_INT = mav.MAVLINK_MSG_ID_MISSION_REQUEST_INT
MISSION_ITEM_INT = mav.MAVLINK_MSG_ID_MISSION_ITEM_INT
COMMAND_ACK = mav.MAVLINK_MSG_ID_COMMAND_ACK
BATTERY_STATUS = mav.MAVLINK_MSG_ID_BATTERY_STATUS
EXTENDED_SYS_STATE = mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
STATUSTEXT = mav.MAVLINK_MSG_ID_STATUSTEXT
HOME_POSITION = mav.MAVLINK_MSG_ID_HOME_POSITION

ATTITUDE = mav.MAVLINK_MSG_ID_ATTITUDE
VFR_HUD = mav.MAVLINK_MSG_ID_VFR_HUD
ADSB_VEHICLE = mav.MAVLINK_MSG_ID_ADSB_VEHICLE

_REJECTS = (mav.MAVLink_bad_data, mav.MAVLink_unknown)


class Frame(NamedTuple):
    """One decoded frame: header fields and the message (pymavlink object or fast tuple)."""

    msg_id: int
    sys_id: int
    comp_id: int
    seq: int
    msg: MavMsg


_new_frame = partial(tuple.__new__, Frame)
"""``Frame`` from one tuple of its fields, without the Python-level ``__new__`` (hot path)."""


@dataclass(frozen=True, slots=True)
class FastType:
    """What the fast path needs of one message type (taken from pymavlink's dialect)."""

    name: str
    crc_extra: bytes  # one byte, appended to the CRC input
    size: int  # full payload length (with extensions)
    unpack: Callable[[bytes], tuple[Any, ...]]
    make: Callable[[tuple[Any, ...]], Any]


FAST_IDS = (
    HEARTBEAT,
    SYS_STATUS,
    SYSTEM_TIME,
    GPS_RAW_INT,
    ATTITUDE,
    GLOBAL_POSITION_INT,
    VFR_HUD,
    EXTENDED_SYS_STATE,
)


def _fast_type(mid: int) -> FastType:
    cls = mav.mavlink_map[mid]
    if any(n > 0 for n in cls.array_lengths):
        raise ValueError(f"{cls.msgname}: array fields are not on the fast path")
    unpacker: struct.Struct = cls.unpacker
    # ordered_fieldnames is the wire order, which is the order struct unpacks in
    tup = namedtuple(cls.msgname, cls.ordered_fieldnames)  # type: ignore[misc]
    return FastType(
        name=cls.msgname,
        crc_extra=bytes([cls.crc_extra]),
        size=unpacker.size,
        unpack=unpacker.unpack,
        make=partial(tuple.__new__, tup),  # = tup._make, without its Python-level call
    )


FAST_TYPES: dict[int, FastType] = {mid: _fast_type(mid) for mid in FAST_IDS}
_MCRF4XX = crc16.mcrf4xx
_V2 = 0xFD
_V1 = 0xFE
_IFLAG_SIGNED = 0x01


_Header = tuple[int, int, int, int, int, int, int]
"""A frame's header as the fast path reads it: (end, msg_id, payload offset, payload length,
sys_id, comp_id, seq); ``end`` is one past its last byte (signature included)."""


def _header(data: bytes, i: int, n: int) -> _Header | None:
    """The header of the MAVLink 2 or 1 frame at ``data[i]`` when the frame ends within
    ``data``, else None (garbage, a frame cut short: pymavlink's to classify). A MAVLink 2 frame
    with incompat flags (signed) has msg_id -1: not for the fast path, pymavlink verifies it."""
    magic = data[i]
    if magic == _V2:
        if i + 12 > n:
            return None
        plen = data[i + 1]
        incompat = data[i + 2]
        end = i + 12 + plen + (13 if incompat & _IFLAG_SIGNED else 0)
        mid = -1 if incompat else data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16)
        return (end, mid, 10, plen, data[i + 5], data[i + 6], data[i + 4]) if end <= n else None
    if magic != _V1 or i + 8 > n:
        return None
    plen = data[i + 1]
    end = i + 8 + plen
    return (end, data[i + 5], 6, plen, data[i + 3], data[i + 4], data[i + 2]) if end <= n else None


def mission_current_id(m: MavMsg) -> int | None:
    """MISSION_CURRENT's ``mission_id`` (an opaque id of the vehicle's mission, MAVLink
    extension of 2023, payload bytes 6-9), read from the raw frame: pymavlink's bundled dialect
    stops at ``mission_mode``. None when the frame does not carry it (MAVLink 1, an older
    autopilot) or it is 0 (the vehicle does not compute one)."""
    buf = bytes(m.get_msgbuf())
    if len(buf) < 12 or buf[0] != _V2:
        return None
    payload = buf[10 : 10 + buf[1]]
    if len(payload) <= 6:
        return None
    value = int.from_bytes((payload[6:10] + bytes(4))[:4], "little")
    return value or None


def unread_ids(read: Iterable[int]) -> frozenset[int]:
    """The dialect's message ids outside ``read``: a :class:`Parser` given them as ``skip``
    frames them without decoding (a PX4 SITL's GCS link streams ATTITUDE_QUATERNION,
    ATTITUDE_TARGET, LOCAL_POSITION_NED, ... at 50 Hz, each a pymavlink decode otherwise)."""
    return frozenset(mav.mavlink_map) - frozenset(read)


def msg_name(mid: int) -> str:
    cls = mav.mavlink_map.get(mid)
    return str(cls.msgname) if cls is not None else f"MSG_{mid}"


SIGNING_EPOCH_S = 1420070400.0  # 2015-01-01T00:00:00Z, the MAVLink signing epoch


def msg_id(m: MavMsg) -> int:
    return int(m._header.msgId)


def src(m: MavMsg) -> tuple[int, int, int]:
    """(system id, component id, sequence number) of a decoded frame."""
    h = m._header
    return int(h.srcSystem), int(h.srcComponent), int(h.seq)


@dataclass(slots=True)
class ParseCounters:
    frames: int = 0
    bad_crc: int = 0
    garbage: int = 0
    unknown_msg: int = 0
    truncated: int = 0
    bad_signature: int = 0
    rejects: int = 0  # every reject above, counted once more: one read tells that one happened
    last_error: str = ""

    @property
    def bad_frames(self) -> int:
        return self.bad_crc + self.garbage + self.unknown_msg + self.truncated + self.bad_signature


class Parser:
    """Sans-IO MAVLink 1/2 parser for one byte stream (or one datagram source)."""

    def __init__(
        self,
        counters: ParseCounters | None = None,
        *,
        key: bytes | None = None,
        fast: bool = True,
        skip: frozenset[int] = frozenset(),
    ) -> None:
        self.counters = counters if counters is not None else ParseCounters()
        # signed links go through pymavlink, which checks the signature
        self.fast = fast and key is None
        # ids the caller never reads: framed and CRC-checked, not decoded (msg None)
        self._skip = {
            mid: bytes([mav.mavlink_map[mid].crc_extra])
            for mid in skip
            if mid in mav.mavlink_map and mid not in FAST_TYPES
        }
        self._mav = mav.MAVLink(None)
        self._mav.robust_parsing = True
        if key is not None:
            self._mav.signing.secret_key = key
            self._mav.signing.allow_unsigned_callback = None

    def _classify(self, reason: str) -> None:
        c = self.counters
        c.last_error = reason
        c.rejects += 1
        r = reason.lower()
        if "crc" in r:
            c.bad_crc += 1
        elif "unknown mavlink message" in r:
            c.unknown_msg += 1
        elif "signature" in r:
            c.bad_signature += 1
        else:
            c.garbage += 1

    def feed(self, data: bytes, *, datagram: bool) -> list[MavMsg]:
        """Decode all complete frames in ``data``; count and drop what is not a frame."""
        try:
            msgs = self._mav.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises bare Exceptions on odd input
            self._classify(f"parser error: {exc}")
            self.reset()
            return []
        out: list[MavMsg] = []
        for m in msgs:
            if type(m) in _REJECTS:
                self._classify(str(getattr(m, "reason", "unknown MAVLink message ID")))
            else:
                out.append(m)
        if datagram and self._mav.buf_len() > 0:
            self.counters.truncated += 1
            self.counters.rejects += 1
            self.counters.last_error = f"truncated frame ({self._mav.buf_len()} bytes left)"
            self.reset()
        self.counters.frames += len(out)
        return out

    def frames(self, data: bytes, *, datagram: bool) -> list[Frame]:
        """Like :meth:`feed` with the header split out; no fast path."""
        out: list[Frame] = []
        for m in self.feed(data, datagram=datagram):
            h = m._header
            out.append(Frame(h.msgId, h.srcSystem, h.srcComponent, h.seq, m))
        return out

    def feed_frames(self, data: bytes) -> list[Frame]:
        """Decode one datagram: hot telemetry on the fast path (see the module docstring),
        the ids of ``skip`` framed and checked but not decoded (``msg`` None), everything else
        through pymavlink. Never raises; rejects are counted."""
        if not self.fast:
            return self.frames(data, datagram=True)
        out: list[Frame] = []
        n = len(data)
        i = 0
        while i < n:
            head = _header(data, i, n)
            if head is None:
                break  # garbage or a frame cut short: pymavlink classifies it from here
            end, mid, hdr, plen, sys_id, comp_id, seq = head
            ft = FAST_TYPES.get(mid)
            skipped = self._skip.get(mid) if ft is None else None
            if skipped is not None:  # a message nobody reads: its header only
                crc = data[end - 2] | (data[end - 1] << 8)
                if _MCRF4XX(skipped, _MCRF4XX(data[i + 1 : end - 2])) != crc:
                    break  # pymavlink classifies and resynchronises from here
                out.append(_new_frame((mid, sys_id, comp_id, seq, None)))
                self.counters.frames += 1
            elif ft is None:  # another message, or a signed frame: pymavlink decodes this one
                out.extend(self.frames(data[i:end], datagram=True))
            else:
                crc = data[end - 2] | (data[end - 1] << 8)
                if _MCRF4XX(ft.crc_extra, _MCRF4XX(data[i + 1 : end - 2])) != crc:
                    break  # pymavlink classifies and resynchronises from here
                payload = data[i + hdr : end - 2]
                if plen != ft.size:  # MAVLink 2 trims trailing zeros; a newer dialect adds
                    payload = (payload + bytes(ft.size))[: ft.size]
                out.append(_new_frame((mid, sys_id, comp_id, seq, ft.make(ft.unpack(payload)))))
                self.counters.frames += 1
            i = end
        if i < n:
            out.extend(self.frames(data[i:], datagram=True))
        return out

    def reset(self) -> None:
        m = self._mav
        m.buf = bytearray()
        m.buf_index = 0
        m.expected_length = mav.HEADER_LEN_V1 + 2
        m.have_prefix_error = False


def signing_timestamp(t_s: float) -> int:
    return max(0, int((t_s - SIGNING_EPOCH_S) * 100_000))


def parse_key(text: str) -> bytes:
    """A 32-byte signing key from 64 hex digits; ValueError otherwise."""
    key = bytes.fromhex(text.strip())
    if len(key) != 32:
        raise ValueError(f"a MAVLink signing key has 32 bytes, got {len(key)}")
    return key


@dataclass(slots=True)
class _Sink:
    last: bytes = b""

    def write(self, data: bytes) -> None:
        self.last = bytes(data)


@dataclass(slots=True)
class Encoder:
    """Packs messages from (``sys_id``, ``comp_id``), signed when ``key`` is set."""

    sys_id: int
    comp_id: int
    key: bytes | None = None
    link_id: int = 0
    _sink: _Sink = field(default_factory=_Sink)
    _mav: Any = None

    def __post_init__(self) -> None:
        self._mav = mav.MAVLink(self._sink, srcSystem=self.sys_id, srcComponent=self.comp_id)
        if self.key is not None:
            s = self._mav.signing
            s.secret_key = self.key
            s.link_id = self.link_id
            s.sign_outgoing = True
            s.timestamp = signing_timestamp(time.time())

    def _send(self, build: Callable[..., MavMsg], *args: Any) -> bytes:
        msg = build(*args)
        self._mav.send(msg)
        return self._sink.last

    @property
    def signed(self) -> bool:
        return self.key is not None

    # --- builders: each returns the packed frame ----------------------------------------
    def heartbeat(
        self,
        *,
        type_: int = 6,
        autopilot: int = 8,
        base_mode: int = 0,
        custom_mode: int = 0,
        system_status: int = 4,
    ) -> bytes:
        return self._send(
            self._mav.heartbeat_encode, type_, autopilot, base_mode, custom_mode, system_status, 3
        )

    def mission_count(self, ts: int, tc: int, count: int) -> bytes:
        return self._send(self._mav.mission_count_encode, ts, tc, count, 0)

    def mission_item_int(self, ts: int, tc: int, item: Any) -> bytes:
        return self._send(
            self._mav.mission_item_int_encode,
            ts,
            tc,
            item.seq,
            item.frame,
            item.command,
            item.current,
            item.autocontinue,
            item.param1,
            item.param2,
            item.param3,
            item.param4,
            item.x,
            item.y,
            item.z,
            item.mission_type,
        )

    def mission_request_list(self, ts: int, tc: int) -> bytes:
        return self._send(self._mav.mission_request_list_encode, ts, tc, 0)

    def mission_request_int(self, ts: int, tc: int, seq: int) -> bytes:
        return self._send(self._mav.mission_request_int_encode, ts, tc, seq, 0)

    def mission_ack(self, ts: int, tc: int, result: int) -> bytes:
        return self._send(self._mav.mission_ack_encode, ts, tc, result, 0)

    def mission_set_current(self, ts: int, tc: int, seq: int) -> bytes:
        return self._send(self._mav.mission_set_current_encode, ts, tc, seq)

    def command_long(
        self,
        ts: int,
        tc: int,
        command: int,
        confirmation: int,
        params: tuple[float, float, float, float, float, float, float],
    ) -> bytes:
        return self._send(self._mav.command_long_encode, ts, tc, command, confirmation, *params)

    def command_int(  # noqa: PLR0917
        self,
        ts: int,
        tc: int,
        frame: int,
        command: int,
        params: tuple[float, float, float, float],
        x: int,
        y: int,
        z: float,
    ) -> bytes:
        return self._send(
            self._mav.command_int_encode, ts, tc, frame, command, 0, 0, *params, x, y, z
        )

    def request_data_stream(self, ts: int, tc: int, stream_id: int, rate_hz: int) -> bytes:
        return self._send(self._mav.request_data_stream_encode, ts, tc, stream_id, rate_hz, 1)

    def raw(self, name: str, *args: Any) -> bytes:
        """Any other message by its pymavlink encoder name (e.g. ``global_position_int``)."""
        return self._send(getattr(self._mav, f"{name}_encode"), *args)
