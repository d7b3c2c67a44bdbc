"""Async TCP readers against a tiny replay server on 127.0.0.1 (ephemeral port)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import pytest

from adapters.adsb import ModeSDecoder, SbsDecoder
from adapters.adsb.net import Backoff, ConnectionStats, read_avr, read_beast, read_sbs
from gcs_utm.model import Measurement

pytestmark = [pytest.mark.network, pytest.mark.timeout(20)]

TOULOUSE = (43.6, 1.44)
FAST = Backoff(initial_s=0.01, max_s=0.05)


async def _serve(chunks: list[bytes]) -> tuple[asyncio.Server, int, list[int]]:
    """Serve ``chunks[k]`` to the k-th connection, then close it (a receiver that drops
    clients). ``connections`` counts clients."""
    connections: list[int] = []

    async def handle(_r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        k = len(connections)
        connections.append(k)
        if k < len(chunks):
            w.write(chunks[k])
            await w.drain()
        w.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    return server, port, connections


async def _take(gen: AsyncIterator[Measurement], n: int) -> list[Measurement]:
    out: list[Measurement] = []
    async for m in gen:
        out.append(m)
        if len(out) == n:
            break
    await gen.aclose()  # type: ignore[attr-defined]
    return out


async def test_beast_reader_reconnects_and_reassembles(beast_bytes):
    # the file split mid-frame over two connections, second half first: the first connection
    # starts mid-frame (bytes skipped), all 4 position frames are in the first half, so the
    # reader must reconnect to get them
    half = len(beast_bytes) // 2
    server, port, conns = await _serve([beast_bytes[half:], beast_bytes[:half]])
    dec = ModeSDecoder(*TOULOUSE)
    stats = ConnectionStats()
    async with server:
        ms = await _take(read_beast("127.0.0.1", port, decoder=dec, backoff=FAST, stats=stats), 4)
    assert len(ms) == 4
    assert {m.icao24 for m in ms} == {"48520a"}
    assert stats.connects >= 2 and len(conns) >= 2
    assert dec.beast_counters.frames >= 237
    assert dec.beast_counters.skipped_bytes > 0 or dec.beast_counters.truncated > 0


async def test_avr_reader(csv_rows):
    text = "".join(f"*{h};\r\n" for _, h in csv_rows[:300]).encode()
    server, port, _ = await _serve([text])
    dec = ModeSDecoder(51.99, 4.375)
    async with server:
        ms = await _take(read_avr("127.0.0.1", port, decoder=dec, backoff=FAST), 50)
    assert len(ms) == 50
    assert all(m.icao24 == "4ca7e9" for m in ms)
    assert dec.counters.corrupt == 0


async def test_sbs_reader_survives_refused_connections():
    line = (
        "MSG,3,1,1,3C6444,1,2024/05/04,12:00:01.500,2024/05/04,12:00:01.510,,12000,,,"
        "50.03190,8.57060,,,0,0,0,0\n"
    )
    # find a free port, start nothing on it first: the reader must retry until it is up
    probe = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
    port = probe.sockets[0].getsockname()[1]
    probe.close()
    await probe.wait_closed()
    stats = ConnectionStats()
    dec = SbsDecoder()
    task = asyncio.create_task(
        _take(read_sbs("127.0.0.1", port, decoder=dec, backoff=FAST, stats=stats), 2)
    )
    await asyncio.sleep(0.1)
    assert stats.failures >= 1 and not task.done()

    async def handle(_r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        w.write(b"garbage\n" + (line * 2).encode())
        await w.drain()
        w.close()

    server = await asyncio.start_server(handle, "127.0.0.1", port)
    async with server:
        ms = await task
    assert len(ms) == 2 and ms[0].icao24 == "3c6444"
    assert dec.counters.malformed >= 1
