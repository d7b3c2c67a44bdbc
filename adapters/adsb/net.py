"""Async TCP clients for dump1090-style feeds: SBS-1 (30003), AVR (30002), Beast (30005).

Each reader is an async generator of :class:`Measurement` that connects, decodes, and on any
connection failure or EOF reconnects with exponential backoff (``initial_s`` doubling up to
``max_s``, reset after a connection that delivered data). It runs until the consumer stops
iterating or the task is cancelled; the socket is closed in ``finally``.

Receipt (and, lacking better, capture) time is ``now_s()`` when a chunk arrives, one time for
every line or frame of the chunk: Beast MLAT counters are receiver-relative, not UTC.
``on_chunk(data, t_s, new_connection)`` sees every chunk as received (the recorder's tap).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

from adapters.adsb.capture import LineSplitter
from adapters.adsb.modes import ModeSDecoder
from adapters.adsb.sbs import SbsDecoder
from gcs_utm.model import Measurement

_log = logging.getLogger(__name__)

_CHUNK = 64 * 1024


@dataclass(frozen=True, slots=True, kw_only=True)
class Backoff:
    initial_s: float = 0.5
    max_s: float = 30.0


@dataclass(slots=True)
class ConnectionStats:
    """One feed's connection: ``failures`` counts refused connects and dropped connections;
    ``up`` is true while connected; ``outages`` counts transitions to down (each logged once,
    however many retries it takes)."""

    connects: int = 0
    failures: int = 0
    bytes: int = 0
    overlong_lines: int = 0
    up: bool = False
    outages: int = 0

    def as_dict(self) -> dict[str, int]:
        return {
            "connects": self.connects,
            "failures": self.failures,
            "bytes": self.bytes,
            "overlong_lines": self.overlong_lines,
            "up": int(self.up),
            "outages": self.outages,
        }


def _down(host: str, port: int, stats: ConnectionStats, why: str, delay_s: float) -> None:
    """Count a failure; the first of an outage is logged as a warning, its retries at debug."""
    stats.failures += 1
    if stats.up or stats.outages == 0:
        stats.outages += 1
        _log.warning(
            "ADS-B feed %s:%d down: %s; reconnecting with backoff (logged once per outage)",
            host,
            port,
            why,
        )
    else:
        _log.debug("ADS-B feed %s:%d: %s; retry in %.1f s", host, port, why, delay_s)
    stats.up = False


async def _chunks(
    host: str, port: int, backoff: Backoff, stats: ConnectionStats
) -> AsyncIterator[tuple[bool, bytes]]:
    """Yield (first chunk of a new connection, data) forever, reconnecting."""
    delay = backoff.initial_s
    while True:
        try:
            reader, writer = await asyncio.open_connection(host, port)
        except OSError as exc:
            _down(host, port, stats, str(exc) or type(exc).__name__, delay)
            await asyncio.sleep(delay)
            delay = min(delay * 2.0, backoff.max_s)
            continue
        stats.connects += 1
        stats.up = True
        _log.info("ADS-B feed %s:%d connected (%d failures before)", host, port, stats.failures)
        got_data = False
        why = "closed by the receiver"
        try:
            while True:
                try:
                    data = await reader.read(_CHUNK)
                except OSError as exc:
                    why = str(exc) or type(exc).__name__
                    break
                if not data:
                    break
                stats.bytes += len(data)
                yield not got_data, data
                got_data = True
        finally:
            writer.close()
            with contextlib.suppress(OSError):
                await writer.wait_closed()
        if got_data:
            delay = backoff.initial_s
        _down(host, port, stats, why, delay)
        await asyncio.sleep(delay)
        delay = min(delay * 2.0, backoff.max_s)


ChunkTap = Callable[[bytes, float, bool], None]
"""``(data, receipt t_s, first chunk of a new connection)``: the recorder's view of a feed."""


async def _timed_chunks(
    host: str,
    port: int,
    backoff: Backoff,
    stats: ConnectionStats,
    *,
    now_s: Callable[[], float],
    on_chunk: ChunkTap | None,
) -> AsyncIterator[tuple[float, bool, bytes]]:
    """``(receipt t_s, new connection, data)``: one receipt time per chunk, the one the
    recorder writes, so a replay of the recording decodes at the same times."""
    async for first, data in _chunks(host, port, backoff, stats):
        t_s = now_s()
        if on_chunk is not None:
            on_chunk(data, t_s, first)
        yield t_s, first, data


async def _lines(
    host: str,
    port: int,
    backoff: Backoff,
    stats: ConnectionStats,
    *,
    now_s: Callable[[], float],
    on_chunk: ChunkTap | None,
) -> AsyncIterator[tuple[float, str]]:
    splitter = LineSplitter()
    async for t_s, first, data in _timed_chunks(
        host, port, backoff, stats, now_s=now_s, on_chunk=on_chunk
    ):
        before = splitter.overlong_lines
        lines = splitter.feed(data, new_connection=first)
        stats.overlong_lines += splitter.overlong_lines - before
        for line in lines:
            yield t_s, line


async def read_sbs(
    host: str,
    port: int,
    *,
    decoder: SbsDecoder | None = None,
    backoff: Backoff | None = None,
    stats: ConnectionStats | None = None,
    now_s: Callable[[], float] = time.time,
    on_chunk: ChunkTap | None = None,
) -> AsyncIterator[Measurement]:
    """Positions from an SBS-1 BaseStation feed (``decoder.counters`` counts bad lines)."""
    dec = decoder if decoder is not None else SbsDecoder()
    lines = _lines(
        host, port, backoff or Backoff(), stats or ConnectionStats(), now_s=now_s, on_chunk=on_chunk
    )
    async for t_s, line in lines:
        m = dec.feed(line, t_s)
        if m is not None:
            yield m


async def read_avr(
    host: str,
    port: int,
    *,
    decoder: ModeSDecoder | None = None,
    backoff: Backoff | None = None,
    stats: ConnectionStats | None = None,
    now_s: Callable[[], float] = time.time,
    on_chunk: ChunkTap | None = None,
) -> AsyncIterator[Measurement]:
    """Positions from an AVR raw text feed (``*8D...;`` lines)."""
    dec = decoder if decoder is not None else ModeSDecoder()
    lines = _lines(
        host, port, backoff or Backoff(), stats or ConnectionStats(), now_s=now_s, on_chunk=on_chunk
    )
    async for t_s, line in lines:
        if not line.strip():
            continue
        m = dec.feed_avr(line, t_s)
        if m is not None:
            yield m


async def read_beast(
    host: str,
    port: int,
    *,
    decoder: ModeSDecoder | None = None,
    backoff: Backoff | None = None,
    stats: ConnectionStats | None = None,
    now_s: Callable[[], float] = time.time,
    on_chunk: ChunkTap | None = None,
) -> AsyncIterator[Measurement]:
    """Positions from a Beast binary feed. A frame split across TCP reads is reassembled; a
    frame cut by a reconnect is dropped and counted in ``decoder.beast_counters``."""
    dec = decoder if decoder is not None else ModeSDecoder()
    chunks = _timed_chunks(
        host, port, backoff or Backoff(), stats or ConnectionStats(), now_s=now_s, on_chunk=on_chunk
    )
    async for t_s, first, data in chunks:
        if first:
            dec.reset_stream()
        for m in dec.feed_beast(data, t_s):
            yield m
