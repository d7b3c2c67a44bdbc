"""Typed seam around pymavlink (which is untyped): encode, sans-IO parse, and message access.

Everything else in `sitl` talks to MAVLink only through this module, so mypy --strict sees
plain `str`/`int`/`float`/`bytes` values. MAVLink 2 framing comes from the v20 dialect.

Invariants:
- one `Encoder` per link (PX4 keeps one sequence counter per MAVLink instance);
- one `Parser` per peer (UDP source address or TCP connection); datagram links call
  `parse_datagram`, which discards a frame left incomplete at the end of a datagram
  (counted as `truncated`) so that a truncated frame cannot swallow the next datagram;
- signing (MAVLink 2 message signing, as PX4 `MAV_SIGN_CFG` / ArduPilot with a key): a `Parser`
  with a key accepts only frames whose signature verifies with it (and whose timestamp moves
  forward per link id, system and component), except RADIO_STATUS, which the MAVLink spec lets
  through unsigned; other frames are dropped and counted (`unsigned_rejected`,
  `bad_signature`). An `Encoder` with a key signs every frame it packs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as _apm

# ardupilotmega includes common: one dialect serves both personalities.
mavlink: Any = _apm

SIGNING_EPOCH_S = 1420070400.0  # 2015-01-01T00:00:00Z: MAVLink signing timestamps count from it
_IFLAG_SIGNED = 0x01
_RADIO_STATUS = int(mavlink.MAVLINK_MSG_ID_RADIO_STATUS)


def signing_timestamp(t_s: float) -> int:
    """MAVLink signing timestamp (10 us units since 2015-01-01) of a UNIX time."""
    return max(0, int((t_s - SIGNING_EPOCH_S) * 100_000))


def _allow_unsigned(_mav: Any, msg_id: int) -> bool:
    # MAVLink spec and PX4/ArduPilot: RADIO_STATUS (injected by radios) may come unsigned.
    return bool(msg_id == _RADIO_STATUS)


@dataclass(slots=True)
class Inbound:
    """One decoded MAVLink message with typed accessors for its fields."""

    type: str
    src_system: int
    src_component: int
    msg_id: int
    raw: Any

    def i(self, name: str, default: int = 0) -> int:
        value = getattr(self.raw, name, default)
        return int(value)

    def f(self, name: str, default: float = 0.0) -> float:
        value = getattr(self.raw, name, default)
        return float(value)

    def has(self, name: str) -> bool:
        return name in getattr(self.raw, "_fieldnames", ())

    def text(self, name: str) -> str:
        value = getattr(self.raw, name, b"")
        if isinstance(value, bytes):
            return value.decode("utf-8", errors="replace").rstrip("\x00")
        return str(value)


@dataclass(slots=True)
class ParseResult:
    messages: list[Inbound]
    garbage: int = 0
    bad_crc: int = 0
    bad_frame: int = 0
    unknown_msgid: int = 0
    truncated: int = 0
    unsigned_rejected: int = 0  # signing on: frame without signature (not RADIO_STATUS)
    bad_signature: int = 0  # signing on: wrong key, or a timestamp that went backwards
    rejected_msg_ids: list[int] = field(default_factory=list)  # of both kinds above


class Parser:
    """Sans-IO MAVLink parser for one peer; never raises on bad input."""

    def __init__(self, key: bytes | None = None) -> None:
        self._mav: Any = mavlink.MAVLink(None)
        self._mav.robust_parsing = True
        if key is not None:
            s = self._mav.signing
            s.secret_key = key
            s.allow_unsigned_callback = _allow_unsigned
            s.timestamp = signing_timestamp(time.time())

    def _classify(self, raw: Any, out: ParseResult) -> None:
        kind = raw.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(raw, "reason", ""))
            if reason == "Invalid signature":
                frame = bytes(getattr(raw, "data", b""))
                if len(frame) >= 10 and frame[2] & _IFLAG_SIGNED:
                    out.bad_signature += 1
                else:
                    out.unsigned_rejected += 1
                if len(frame) >= 10:
                    out.rejected_msg_ids.append(frame[7] | (frame[8] << 8) | (frame[9] << 16))
            elif "prefix" in reason:
                out.garbage += 1
            elif "CRC" in reason:
                out.bad_crc += 1
            else:
                out.bad_frame += 1
            return
        if kind.startswith("UNKNOWN_"):
            out.unknown_msgid += 1
            return
        out.messages.append(
            Inbound(
                type=kind,
                src_system=int(raw.get_srcSystem()),
                src_component=int(raw.get_srcComponent()),
                msg_id=int(raw.get_msgId()),
                raw=raw,
            )
        )

    def parse_stream(self, data: bytes) -> ParseResult:
        out = ParseResult(messages=[])
        try:
            msgs = self._mav.parse_buffer(data) or []
        except Exception:  # pymavlink may still raise on odd input: count, never crash
            out.bad_frame += 1
            self._reset()
            return out
        for raw in msgs:
            self._classify(raw, out)
        return out

    def parse_datagram(self, data: bytes) -> ParseResult:
        out = self.parse_stream(data)
        if self._mav.buf_len() > 0:
            out.truncated += 1
            self._reset()
        return out

    def _reset(self) -> None:
        self._mav.buf = bytearray()
        self._mav.buf_index = 0
        self._mav.expected_length = mavlink.HEADER_LEN_V1 + 2


class Encoder:
    """Packs messages as one MAVLink 2 sender (system id, component id, own sequence), signed
    with `key` (link id `link_id`) when one is given."""

    def __init__(
        self, sys_id: int, comp_id: int = 1, *, key: bytes | None = None, link_id: int = 0
    ) -> None:
        self._mav: Any = mavlink.MAVLink(None, srcSystem=sys_id, srcComponent=comp_id)
        if key is not None:
            s = self._mav.signing
            s.secret_key = key
            s.link_id = link_id
            s.sign_outgoing = True
            s.timestamp = signing_timestamp(time.time())

    def pack(self, name: str, **fields: Any) -> bytes:
        encode = getattr(self._mav, name.lower() + "_encode")
        return bytes(encode(**fields).pack(self._mav))


def msg_id_of(name: str) -> int | None:
    """MAVLink message id for a message name, or None if the dialect lacks it."""
    value = getattr(mavlink, "MAVLINK_MSG_ID_" + name.upper(), None)
    return None if value is None else int(value)


def name_of(msg_id: int) -> str | None:
    cls = mavlink.mavlink_map.get(msg_id)
    return None if cls is None else str(cls.msgname)


def const(name: str) -> int:
    """A MAVLink enum constant by name (e.g. "MAV_CMD_NAV_WAYPOINT")."""
    return int(getattr(mavlink, name))
