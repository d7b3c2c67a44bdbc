"""The messages of a recorded ``.tlog``, decoded as the service decodes a link (for tests that
check what was recorded)."""

from __future__ import annotations

from pathlib import Path

from adapters.mavlink import wire
from adapters.tlog import TlogReader


def tlog_messages(path: Path) -> list[tuple[float, wire.MavMsg]]:
    """``(record t_s, decoded message)`` of every valid record of ``path``."""
    parser = wire.Parser()
    return [
        (rec.t_s, m) for rec in TlogReader(path) for m in parser.feed(rec.packet, datagram=True)
    ]
