"""The one place in the tlog adapter that touches pymavlink (untyped): CRC-extra lookup and
decoding one packet. Uses the ``all`` dialect so ArduPilot/PX4-specific messages in a tlog are
checked and decoded too."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import all as _dialect
from pymavlink.generator.mavcrc import x25crc

MavMsg = Any
"""A decoded pymavlink message (untyped library object)."""

_CRC_EXTRA: dict[int, int] = {
    int(msgid): int(cls.crc_extra) for msgid, cls in _dialect.mavlink_map.items()
}


def crc_extra(msgid: int) -> int | None:
    """CRC_EXTRA of ``msgid`` in the dialect, ``None`` when the id is unknown."""
    return _CRC_EXTRA.get(msgid)


def x25(data: bytes) -> int:
    """MAVLink's X.25 CRC-16 of ``data``."""
    return int(x25crc(data).crc)


class PacketDecoder:
    """Decodes whole MAVLink packets one at a time (sans IO). ``decode`` returns ``None`` for
    a packet pymavlink rejects; ``errors`` counts them."""

    def __init__(self) -> None:
        self._mav: Any = _dialect.MAVLink(None)
        self._mav.robust_parsing = True
        self.errors = 0

    def decode(self, packet: bytes) -> MavMsg | None:
        try:
            msgs = self._mav.parse_buffer(packet)
        except _dialect.MAVError:
            self.errors += 1
            return None
        if not msgs:
            self.errors += 1
            return None
        m = msgs[0]
        if m.get_type() == "BAD_DATA":
            self.errors += 1
            return None
        return m


def msg_type(m: MavMsg) -> str:
    return str(m.get_type())
