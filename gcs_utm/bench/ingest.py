"""MAVLink ingest: GLOBAL_POSITION_INT datagrams through a udpin link into Measurements.

Throughput: a sender *process* blasts pre-encoded datagrams from 4 sockets (sysids 1..250 on
each: 1,000 vehicles) at 127.0.0.1 as fast as it can; the hub (this process, one core) turns
them into Measurements; per_s = measurements / (last - first arrival). Drops (kernel buffer
overflow when the hub is saturated) are reported. Latency: the sender paces 10,000 msg/s;
latency = on_measurement time - receipt time stamped at datagram_received (receipt-to-
measurement), p99 over all messages of a run."""

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


async def _one(n: int, vehicles: int, rate: float) -> tuple[_Sink, int]:
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from gcs_utm.clock import RealClock

    sink = _Sink()
    hub = MavlinkHub(
        MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=1.0), RealClock(), sink
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
    thr_ms: list[float] = []
    per_s: list[float] = []
    drops: list[int] = []
    for _ in range(args.runs):
        sink, n = asyncio.run(_one(args.messages, args.vehicles, 0.0))
        per_s.append(sink.n / max(1e-9, sink.last - sink.first))
        thr_ms.append((sink.last - sink.first) * 1000.0)
        drops.append(n - sink.n)
    lat_p99: list[float] = []
    lat_all: list[float] = []
    for _ in range(args.runs):
        sink, _n = asyncio.run(_one(int(args.rate * 2), args.vehicles, args.rate))
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
    return [rec1, rec2]
