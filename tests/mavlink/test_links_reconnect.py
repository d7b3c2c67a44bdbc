"""Stream links survive their peer (issue 26 item 5): the hub starts although the TCP peer
is not listening yet, connects when it comes, marks the vehicle lost when the connection
drops (a COMMUNICATION_FAILURE hazard, no flood of send warnings), reconnects with backoff and
hears the vehicle again; ArduPilot is asked for its streams again. A serial link (a pty) the
same. Local TCP servers and ptys only."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import pty
import socket
import time
import tty
from pathlib import Path
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.transport import Backoff
from gcs_utm.clock import RealClock
from gcs_utm.model import ThreatKind
from tests.mavlink.conftest import Sink

pytestmark = [pytest.mark.network, pytest.mark.timeout(60)]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _until(cond: Any, timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out: {what}")
        await asyncio.sleep(0.01)


class TcpVehicle:
    """A vehicle listening on TCP like ArduPilot SITL (5760): on each connection it sends a
    heartbeat and a position every 50 ms and records what it receives."""

    def __init__(self, port: int, *, autopilot: int = 3, sys_id: int = 1) -> None:
        self.port = port
        self.autopilot = autopilot
        self.mav = mav.MAVLink(None, srcSystem=sys_id, srcComponent=1)
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.received: list[Any] = []
        self.server: asyncio.Server | None = None
        self.writers: list[asyncio.StreamWriter] = []
        self.boot_ms = 0

    async def start(self) -> None:
        self.server = await asyncio.start_server(self._client, "127.0.0.1", self.port)

    async def stop(self) -> None:
        """Like a killed SITL: stop listening and drop every connection."""
        assert self.server is not None
        self.server.close()
        for w in self.writers:
            w.transport.abort()
        self.writers.clear()
        await self.server.wait_closed()
        self.server = None

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.writers.append(writer)
        self.boot_ms = 0  # a restarted autopilot counts from 0
        talk = asyncio.create_task(self._talk(writer))
        try:
            while data := await reader.read(4096):
                for m in self.parser.parse_buffer(data) or []:
                    self.received.append(m)
        except ConnectionError:
            pass
        finally:
            talk.cancel()

    async def _talk(self, writer: asyncio.StreamWriter) -> None:
        while not writer.is_closing():
            self.boot_ms += 50
            hb = self.mav.heartbeat_encode(2, self.autopilot, 129, 0, 4, 3)
            gpi = self.mav.global_position_int_encode(
                self.boot_ms, 473977418, 85455939, 500000, 20000, 0, 0, 0, 0
            )
            writer.write(hb.pack(self.mav) + gpi.pack(self.mav))
            await asyncio.sleep(0.05)

    def intervals(self) -> int:
        return sum(1 for m in self.received if m.get_type() == "COMMAND_LONG" and m.command == 511)


async def test_tcp_link_up_late_down_and_back(caplog: pytest.LogCaptureFixture) -> None:
    port = _free_port()
    sink = Sink()
    cfg = MavlinkConfig(
        links=(f"tcp:127.0.0.1:{port}",),
        reconnect_min_s=0.05,
        reconnect_max_s=0.2,
        heartbeat_period_s=0.02,
        health_period_s=0.1,
    )
    v = TcpVehicle(port)
    with caplog.at_level(logging.INFO):
        async with MavlinkHub(cfg, RealClock(), sink) as hub:
            # started although nobody listens: one clear line, then retries in the background
            [ls] = hub.links()
            assert not ls.up and ls.failures == 1 and "111" in ls.last_error  # ECONNREFUSED
            assert any("not up" in r.getMessage() for r in caplog.records)
            await asyncio.sleep(0.5)
            assert hub.links()[0].failures >= 3
            await v.start()
            await _until(lambda: bool(sink.measurements), 5.0, "vehicle not heard once up")
            assert hub.links()[0].up and hub.links()[0].connects == 1
            await _until(lambda: v.intervals() >= 6, 2.0, "streams not requested")
            first = v.intervals()
            # the peer dies: the vehicle is lost, and nothing floods the log
            await v.stop()
            await _until(lambda: not hub.links()[0].up, 2.0, "link not seen down")
            lost = [h for h in sink.hazards if h.kind is ThreatKind.COMMUNICATION_FAILURE]
            assert len(lost) == 1 and lost[0].sys_id == 1 and "down" in lost[0].message
            n = len(sink.measurements)
            await asyncio.sleep(0.6)  # 30 heartbeat periods while down
            assert hub.counters.links_down == 1
            assert hub.links()[0].dropped_down >= 10
            assert hub.counters.dropped_link_down >= 10
            # it comes back (a restarted SITL): reconnected, heard again, streams asked again
            v2 = TcpVehicle(port)
            v2.received = []
            await v2.start()
            await _until(lambda: len(sink.measurements) > n + 3, 5.0, "not heard after restart")
            assert hub.links()[0].connects == 2 and hub.links()[0].up
            await _until(lambda: v2.intervals() >= first, 2.0, "streams not requested again")
            await v2.stop()
    noisy = [r for r in caplog.records if "socket.send() raised exception" in r.getMessage()]
    assert not noisy
    retries = [r for r in caplog.records if "still not up" in r.getMessage()]
    assert len(retries) <= 2  # rate-limited: one per outage here (at most one per 30 s)


async def test_serial_link_reopens_when_the_device_comes_back(tmp_path: Path) -> None:
    dev = tmp_path / "ttyV0"

    def new_pty() -> int:
        master, slave = pty.openpty()
        tty.setraw(master)
        if dev.is_symlink():
            dev.unlink()
        dev.symlink_to(os.ttyname(slave))
        os.close(slave)  # the hub opens it by name
        return master

    master = new_pty()
    sink = Sink()
    cfg = MavlinkConfig(
        links=(f"serial:{dev}:57600",),
        reconnect_min_s=0.05,
        reconnect_max_s=0.1,
        health_period_s=0.1,
    )
    enc = mav.MAVLink(None, srcSystem=3, srcComponent=1)

    def send() -> None:
        os.write(master, enc.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(enc))

    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        send()
        await _until(lambda: bool(sink.vehicles), 3.0, "serial vehicle not heard")
        os.close(master)  # the cable is pulled: reads fail with EIO
        dev.unlink()
        await _until(lambda: not hub.links()[0].up, 3.0, "serial link not seen down")
        assert [h.sys_id for h in sink.hazards] == [3]
        await asyncio.sleep(0.3)
        assert hub.links()[0].failures >= 1  # the device is gone: retried
        master = new_pty()
        await _until(lambda: hub.links()[0].up, 3.0, "serial link not reopened")
        n = len(sink.statuses)
        send()
        await _until(lambda: len(sink.statuses) > n, 3.0, "not heard after reopen")
        assert hub.links()[0].connects == 2
    os.close(master)


def test_backoff_doubles_up_to_its_bound_and_refuses_inverted_bounds() -> None:
    b = Backoff(min_s=0.5, max_s=4.0)
    assert [b.delay_s(n) for n in range(1, 7)] == [0.5, 1.0, 2.0, 4.0, 4.0, 4.0]
    assert b.delay_s(10_000) == 4.0
    with pytest.raises(ValueError, match="min_s <= max_s"):
        Backoff(min_s=2.0, max_s=1.0)
    with pytest.raises(ValueError, match="must not exceed"):
        MavlinkConfig(reconnect_min_s=2.0, reconnect_max_s=1.0)


async def test_a_peer_that_does_not_answer_does_not_hold_the_start(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import adapters.mavlink.transport as transport

    monkeypatch.setattr(transport, "_CONNECT_TIMEOUT_S", 0.3)
    # a listener that never accepts, its queue full: further SYNs go unanswered
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(0)
    port = srv.getsockname()[1]
    fillers = []
    for _ in range(4):
        c = socket.socket()
        c.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            c.connect(("127.0.0.1", port))
        fillers.append(c)
    await asyncio.sleep(0.2)
    cfg = MavlinkConfig(links=(f"tcp:127.0.0.1:{port}",), reconnect_min_s=5.0)
    t0 = time.monotonic()
    try:
        async with MavlinkHub(cfg, RealClock(), Sink()) as hub:
            assert time.monotonic() - t0 < 2.0
            [ls] = hub.links()
            assert not ls.up and "no answer within 0.3 s" in ls.last_error
    finally:
        for c in fillers:
            c.close()
        srv.close()
