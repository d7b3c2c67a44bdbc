"""The one place in the tlog adapter that touches pymavlink (untyped): the CRC-extra lookup
and the X.25 CRC. Uses the ``all`` dialect so ArduPilot/PX4-specific messages in a tlog are
checked too."""

from __future__ import annotations

from pymavlink.dialects.v20 import all as _dialect
from pymavlink.generator.mavcrc import x25crc

_CRC_EXTRA: dict[int, int] = {
    int(msgid): int(cls.crc_extra) for msgid, cls in _dialect.mavlink_map.items()
}


def crc_extra(msgid: int) -> int | None:
    """CRC_EXTRA of ``msgid`` in the dialect, ``None`` when the id is unknown."""
    return _CRC_EXTRA.get(msgid)


def x25(data: bytes) -> int:
    """MAVLink's X.25 CRC-16 of ``data``."""
    return int(x25crc(data).crc)
