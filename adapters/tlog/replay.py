"""Replaying a ``.tlog`` into the pipeline.

- :func:`iter_messages` yields ``(t_s, pymavlink message)`` for every record whose packet
  decodes; the record time is the capture time.
- :func:`replay` calls ``on_packet(t_s, packet)`` for every record, paced at real speed
  (``speed=1``), a speed factor, or as fast as possible (``speed=None``, yielding to the loop
  every ``yield_every`` records). Pacing follows the record times from the first record, on
  the monotonic clock, so a slow consumer catches up instead of drifting. Raw packets are
  handed on so the MAVLink adapter decodes them exactly as it decodes a live link.

The file is read in chunks on the loop thread; a chunk (256 KiB) is parsed in a few ms.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from adapters.tlog._mavlink import MavMsg, PacketDecoder
from adapters.tlog.reader import TlogCounters, TlogReader


def iter_messages(
    path: str | Path, *, counters: TlogCounters | None = None
) -> Iterator[tuple[float, MavMsg]]:
    """``(record t_s, decoded message)`` for each valid record of ``path``. Corrupt records
    are skipped; pass ``counters`` to read how many (filled as iteration proceeds)."""
    reader = TlogReader(path)
    decoder = PacketDecoder()
    try:
        for rec in reader:
            m = decoder.decode(rec.packet)
            if m is not None:
                yield rec.t_s, m
    finally:
        if counters is not None:
            for name, value in reader.counters.as_dict().items():
                setattr(counters, name, value)
            counters.corrupt_chunks += decoder.errors


@dataclass(frozen=True, slots=True, kw_only=True)
class ReplayStats:
    records: int
    first_t_s: float | None
    last_t_s: float | None
    wall_s: float
    counters: TlogCounters

    @property
    def duration_s(self) -> float:
        if self.first_t_s is None or self.last_t_s is None:
            return 0.0
        return self.last_t_s - self.first_t_s


async def replay(
    path: str | Path,
    on_packet: Callable[[float, bytes], None],
    *,
    speed: float | None = None,
    yield_every: int = 500,
    monotonic: Callable[[], float] = time.monotonic,
) -> ReplayStats:
    """Feed every record of ``path`` to ``on_packet(t_s, packet)``; see the module doc."""
    if speed is not None and not speed > 0.0:
        raise ValueError(f"speed must be positive or None, got {speed}")
    reader = TlogReader(path)
    start_wall = monotonic()
    first: float | None = None
    last: float | None = None
    n = 0
    for rec in reader:
        if first is None:
            first = rec.t_s
        if speed is not None:
            due = start_wall + (rec.t_s - first) / speed
            delay = due - monotonic()
            if delay > 0.0:
                await asyncio.sleep(delay)
        elif n % yield_every == 0:
            await asyncio.sleep(0)
        on_packet(rec.t_s, rec.packet)
        last = rec.t_s
        n += 1
    return ReplayStats(
        records=n,
        first_t_s=first,
        last_t_s=last,
        wall_s=monotonic() - start_wall,
        counters=reader.counters,
    )
