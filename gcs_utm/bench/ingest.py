"""MAVLink ingest: GLOBAL_POSITION_INT datagrams through a udpin link into Measurements.

Throughput: a sender *process* blasts pre-encoded datagrams from 4 sockets (sysids 1..250 on
each: 1,000 vehicles) at 127.0.0.1 as fast as it can; the hub (this process, one core) turns
them into Measurements; per_s = measurements / (last - first arrival). Drops (kernel buffer
overflow when the hub is saturated) are reported. Latency: the sender paces 10,000 msg/s;
latency = on_measurement time - receipt time stamped at datagram_received (receipt-to-
measurement), p99 over all messages of a run. In-process: ``_on_chunk`` on pre-encoded
datagrams without a socket, fast path vs pymavlink for everything (``fast_decode`` false), the
per-core decode + dispatch cost."""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import os
import socket
import statistics
import time

from gcs_utm.bench.timing import summary

NAME = "ingest"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--messages", type=int, default=60_000)
    p.add_argument("--vehicles", type=int, default=1000)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--rate", type=float, default=10_000.0, help="latency run send rate")
    p.add_argument(
        "--send-rate",
        type=float,
        default=0.0,
        help="throughput runs: paced send rate (0 = as fast as the sender can)",
    )
    p.add_argument(
        "--decode",
        choices=("fast", "pymavlink"),
        default="fast",
        help="socket runs: fast path or pymavlink for everything (fast_decode=false)",
    )


def _sender(port: int, n: int, vehicles: int, rate: float, start: float) -> None:
    os.environ["MAVLINK20"] = "1"
    from pymavlink.dialects.v20 import common as mav

    socks = [
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range((vehicles + 249) // 250)
    ]
    encs = [mav.MAVLink(None, srcSystem=i % 250 + 1, srcComponent=1) for i in range(vehicles)]
    frames = []
    for i in range(n):
        v = i % vehicles
        e = encs[v]
        frames.append(
            (
                socks[v // 250],
                e.global_position_int_encode(
                    1000 + i, 473977418 + v, 85455939, 500000, 10000, 1, 2, 3, 0
                ).pack(e),
            )
        )
        e.seq = (e.seq + 1) % 256
    while time.time() < start:
        time.sleep(0.001)
    dest = ("127.0.0.1", port)
    t0 = time.perf_counter()
    for i, (s, f) in enumerate(frames):
        if rate > 0:
            while time.perf_counter() - t0 < i / rate:
                pass
        s.sendto(f, dest)


class _Sink:
    def __init__(self) -> None:
        self.n = 0
        self.first = 0.0
        self.last = 0.0
        self.lat: list[float] = []

    def on_measurement(self, m: object) -> None:
        now = time.time()
        if self.n == 0:
            self.first = now
        self.last = now
        self.n += 1
        self.lat.append(now - m.receipt_t_s)  # type: ignore[attr-defined]

    def on_status(self, s: object) -> None: ...
    def on_hazard(self, h: object) -> None: ...
    def on_vehicle(self, v: object) -> None: ...
    def on_link_health(self, h: object) -> None: ...


def _frames(n: int, vehicles: int, boot0: int = 1000) -> list[bytes]:
    os.environ["MAVLINK20"] = "1"
    from pymavlink.dialects.v20 import common as mav

    encs = [mav.MAVLink(None, srcSystem=i % 250 + 1, srcComponent=1) for i in range(vehicles)]
    out = []
    for i in range(n):
        e = encs[i % vehicles]
        out.append(
            bytes(
                e.global_position_int_encode(
                    boot0 + i, 473977418 + i % vehicles, 85455939, 500000, 10000, 1, 2, 3, 0
                ).pack(e)
            )
        )
        e.seq = (e.seq + 1) % 256
    return out


def _inprocess(n: int, vehicles: int, runs: int, fast: bool) -> list[float]:
    """ms to push ``n`` datagrams through ``_on_chunk`` (1,000 vehicles on 4 addresses)."""
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from gcs_utm.clock import RealClock

    passes = [_frames(n, vehicles, 1000 + r * n) for r in range(runs + 1)]
    addrs = [("127.0.0.1", 20000 + (i % vehicles) // 250) for i in range(n)]

    async def go() -> list[float]:
        sink = _Sink()
        cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), fast_decode=fast)
        hub = MavlinkHub(cfg, RealClock(), sink)
        await hub.start()
        link = next(iter(hub._links.values()))
        on_chunk = hub._on_chunk
        out: list[float] = []
        for r, frames in enumerate(passes):
            t0 = time.perf_counter()
            for f, a in zip(frames, addrs, strict=True):
                on_chunk(link, f, a)
            if r:  # the first run discovers the vehicles: warm-up
                out.append((time.perf_counter() - t0) * 1000.0)
        await hub.close()
        if sink.n != n * (runs + 1):
            raise RuntimeError(f"{sink.n} measurements of {n * (runs + 1)}")
        return out

    return asyncio.run(go())


async def _one(n: int, vehicles: int, rate: float, fast: bool = True) -> tuple[_Sink, int]:
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from gcs_utm.clock import RealClock

    sink = _Sink()
    hub = MavlinkHub(
        MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=1.0, fast_decode=fast),
        RealClock(),
        sink,
    )
    await hub.start()
    port = hub.local_port(next(iter(hub._links)))
    proc = mp.get_context("spawn").Process(
        target=_sender, args=(port, n, vehicles, rate, time.time() + 1.5)
    )
    proc.start()
    deadline = time.time() + 30.0
    while proc.is_alive() and time.time() < deadline:
        await asyncio.sleep(0.05)
    await asyncio.sleep(0.3)
    await hub.close()
    proc.join()
    return sink, n


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    fast = args.decode == "fast"
    recs: list[dict[str, object]] = []
    for path in (True, False):
        ms = _inprocess(args.messages, args.vehicles, args.runs, path)
        recs.append(
            summary(
                f"ingest_inprocess_{'fast' if path else 'pymavlink'}",
                args.messages,
                ms,
                items_per_run=args.messages,
                vehicles=args.vehicles,
            )
        )
    thr_ms: list[float] = []
    per_s: list[float] = []
    drops: list[int] = []
    for _ in range(args.runs):
        sink, n = asyncio.run(_one(args.messages, args.vehicles, args.send_rate, fast))
        per_s.append(sink.n / max(1e-9, sink.last - sink.first))
        thr_ms.append((sink.last - sink.first) * 1000.0)
        drops.append(n - sink.n)
    lat_p99: list[float] = []
    lat_all: list[float] = []
    for _ in range(args.runs):
        sink, _n = asyncio.run(_one(int(args.rate * 2), args.vehicles, args.rate, fast))
        q = statistics.quantiles(sink.lat, n=100)
        lat_p99.append(q[98] * 1000.0)
        lat_all.append(statistics.median(sink.lat) * 1000.0)
    rec1 = summary(
        "ingest_throughput",
        args.messages,
        thr_ms,
        items_per_run=None,
        vehicles=args.vehicles,
        dropped_per_run=drops,
        decode=args.decode,
        send_rate_per_s=args.send_rate or "max",
    )
    rec1["per_s"] = round(statistics.median(per_s), 1)
    rec2 = summary(
        "ingest_latency_10k",
        int(args.rate * 2),
        lat_p99,
        vehicles=args.vehicles,
        rate_per_s=args.rate,
        median_latency_ms=round(statistics.median(lat_all), 4),
    )
    rec2["note"] = "median_ms/min_ms/max_ms are the per-run p99 receipt-to-measurement latency"
    rec2["decode"] = args.decode
    return [*recs, rec1, rec2]
