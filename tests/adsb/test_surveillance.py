"""SurveillanceService against receiver feeds served on loopback (ephemeral ports): an SBS-1
server, a Beast server fed from the shipped capture, and a feed that is down."""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable

import pytest

from adapters.adsb.config import AdsbConfig
from gcs_utm.clock import RealClock
from gcs_utm.model import Measurement, MeasurementSource
from gcs_utm.services.surveillance import SurveillanceService
from tests.adsb.sbs_lines import sbs_position, sbs_velocity

pytestmark = [pytest.mark.network, pytest.mark.timeout(30)]

TOULOUSE = (43.6, 1.44)


async def _server(payload: bytes) -> tuple[asyncio.Server, int]:
    """Serve ``payload`` to each client, then keep the connection open (a live receiver)."""

    async def handle(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        w.write(payload)
        await w.drain()
        await r.read()  # until the client goes
        w.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]


def _closed_port() -> int:
    """A loopback port nobody listens on (bound, then released)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port: int = s.getsockname()[1]
    s.close()
    return port


async def _until(cond: Callable[[], bool], timeout_s: float = 10.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not cond():
        assert loop.time() < end, "timed out"
        await asyncio.sleep(0.02)


def test_disabled_or_port_zero_means_no_feed() -> None:
    got: list[Measurement] = []
    assert SurveillanceService(AdsbConfig(), RealClock(), got.append).feeds == []
    on = AdsbConfig(enabled=True)  # by default the SBS-1 feed alone (one per receiver)
    assert [f.kind for f in SurveillanceService(on, RealClock(), got.append).feeds] == ["sbs"]
    raw = AdsbConfig(enabled=True, sbs_port=0, beast_port=30005)
    assert [f.kind for f in SurveillanceService(raw, RealClock(), got.append).feeds] == ["beast"]


async def test_feeds_are_decoded_counted_and_a_down_feed_is_logged_once(
    beast_bytes: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    sbs = [
        sbs_velocity("abc123", 100.0, 90.0, 0.0),
        sbs_position("abc123", 43.61, 1.40, 1000.0, callsign="TEST1"),
        "MSG,3,garbage",  # malformed: a reject
        sbs_position("abc123", 43.61, 1.41, 1000.0),
        sbs_position("abc123", 43.61, 1.42, 1000.0),
    ]
    sbs_server, sbs_port = await _server(("\r\n".join(sbs) + "\r\n").encode())
    beast_server, beast_port = await _server(beast_bytes)
    down_port = _closed_port()
    cfg = AdsbConfig(
        enabled=True,
        host="127.0.0.1",
        sbs_port=sbs_port,
        beast_port=beast_port,
        avr_port=down_port,
        receiver_position_known=True,
        receiver_lat_deg=TOULOUSE[0],
        receiver_lon_deg=TOULOUSE[1],
        reconnect_initial_s=0.01,
        reconnect_max_s=0.05,
    )
    got: list[Measurement] = []
    svc = SurveillanceService(cfg, RealClock(), got.append)
    caplog.set_level(logging.DEBUG, logger="adapters.adsb.net")
    async with sbs_server, beast_server:
        task = asyncio.create_task(svc.run())
        try:
            await _until(lambda: len(got) >= 3 + 4)
            await _until(lambda: svc.feeds[1].connection.failures >= 5)
        finally:
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
    stats = svc.stats()
    s = stats[f"sbs:127.0.0.1:{sbs_port}"]
    assert (s["frames"], s["positions"], s["rejects"], s["measurements"]) == (5, 3, 1, 3)
    assert s["up"] == 1 and s["connects"] == 1
    b = stats[f"beast:127.0.0.1:{beast_port}"]
    assert (b["frames"], b["positions"], b["rejects"], b["measurements"]) == (239, 4, 0, 4)
    a = stats[f"avr:127.0.0.1:{down_port}"]
    assert a["up"] == 0 and a["connects"] == 0 and a["outages"] == 1 and a["failures"] >= 5
    # a feed that stays down is one warning, however many retries
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len([r for r in warnings if f":{down_port} down" in r.getMessage()]) == 1
    assert all(m.source is MeasurementSource.ADSB for m in got)
    sbs_ms = [m for m in got if m.icao24 == "abc123"]
    assert [round(m.lon_deg, 2) for m in sbs_ms] == [1.40, 1.41, 1.42]
    assert sbs_ms[0].callsign == "TEST1" and sbs_ms[0].vel_ned_mps is not None
    assert sbs_ms[0].alt_amsl_m == pytest.approx(304.8)
    assert {m.icao24 for m in got} == {"abc123", "48520a"}


async def test_a_dropped_connection_is_logged_once_and_reconnected(
    caplog: pytest.LogCaptureFixture,
) -> None:
    lines = (sbs_position("abc123", 43.61, 1.40, 1000.0) + "\n").encode()
    clients: list[int] = []

    async def handle(_r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        clients.append(1)
        w.write(lines)
        await w.drain()
        w.close()  # the receiver drops every client after one line

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    cfg = AdsbConfig(
        enabled=True,
        sbs_port=port,
        avr_port=0,
        beast_port=0,
        reconnect_initial_s=0.01,
        reconnect_max_s=0.02,
    )
    got: list[Measurement] = []
    svc = SurveillanceService(cfg, RealClock(), got.append)
    caplog.set_level(logging.INFO, logger="adapters.adsb.net")
    async with server:
        task = asyncio.create_task(svc.run())
        try:
            await _until(lambda: len(got) >= 3)
        finally:
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
    c = svc.feeds[0].connection
    assert c.connects >= 3 and c.outages >= 2  # each drop after data is a new outage
    downs = [r for r in caplog.records if "down" in r.getMessage()]
    assert len(downs) == c.outages
