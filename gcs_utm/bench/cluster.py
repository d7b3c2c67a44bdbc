"""Scale-out figures (docs/scale-out.md): region failover after ``kill -9``, store write
throughput on SQLite and PostgreSQL, and broker throughput of region traffic messages.

- ``cluster.failover``: a member process holds a region; it is killed with SIGKILL and a
  standby member in this process takes the region over; the time from the kill to the
  standby's confirmed lease (``--runs`` times). The bound is ``lease_s + renew_s``.
- ``cluster.store_tracks`` (per backend): track rows (latest + history) committed per second
  through the one :class:`StoreWriter`, ``--batches`` batches of ``--tracks`` tracks offered
  at once and flushed: the writer's capacity, what one instance can persist.
- ``cluster.store_decisions`` (per backend): must-keep audit rows committed per second, each
  awaited (one commit round trip each when nothing else is queued).
- ``cluster.store_tracks_shared``: ``--writers`` processes (instances), each with its own
  writer and its own track ids, writing to the one PostgreSQL database at once: the rows per
  second all of them commit together (what a shared store gives N instances).
- ``cluster.exchange``: the region exchange itself: one instance publishes its tracks near
  the border, the neighbour receives them through its halo subscription; milliseconds from
  the publish call to the neighbour's callback (the cross-region part of detection latency;
  detection adds at most one publication period and one monitoring period).
- ``cluster.broker``: a mosquitto on loopback (when installed), one publisher and one
  subscriber: region traffic messages (``--tracks-per-msg`` tracks in the existing traffic
  encoding) through the broker per second, QoS 0.

PostgreSQL: ``--url``, a database the run may fill (a deployment's own server, or from a
checkout the private one ``python -m tests.store.pgserver`` starts, fsync on).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from gcs_utm.bench.timing import summary

NAME = "cluster"
IN_ALL = False  # starts PostgreSQL, mosquitto and member processes: run it by name

_OWNER = """
import asyncio, sys
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.cluster.member import ClusterMember

async def main():
    cfg = ClusterConfig(instance="owner", region="c0r0", standby=False, columns=2, rows=1,
        lease_s=float(sys.argv[2]), renew_s=float(sys.argv[3]))
    async def gained(region, lease):
        print("gained", region, flush=True)
    async def lost(region, lease):
        pass
    m = ClusterMember(sys.argv[1], cfg, instance="owner", epoch=int(sys.argv[4]),
        on_gained=gained, on_lost=lost)
    await m.start()
    await m.run()

asyncio.run(main())
"""


_WRITER = """
import sys, time
from gcs_utm.bench.cluster import _track
from gcs_utm.store import StoreConfig, StoreWriter
url, k, tracks, batches = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
w = StoreWriter(url, StoreConfig(queue_size=10000))
data = [[_track(k * 1_000_000 + i, float(b)) for i in range(tracks)] for b in range(batches)]
w.write_tracks(data[0]); w.flush(60)
print("ready", flush=True)
sys.stdin.readline()
t0 = time.perf_counter()
for batch in data[1:]:
    assert w.write_tracks(batch) is not None
w.flush(600)
print(time.perf_counter() - t0, flush=True)
w.close()
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--url", default="", help="postgresql:// URL of a database the run may fill (required)"
    )
    p.add_argument("--runs", type=int, default=3, help="failovers timed")
    p.add_argument("--lease-s", type=float, default=3.0, help="[cluster] lease_s")
    p.add_argument("--renew-s", type=float, default=1.0, help="[cluster] renew_s")
    p.add_argument("--tracks", type=int, default=1000, help="tracks per store batch")
    p.add_argument("--batches", type=int, default=30, help="store batches per backend")
    p.add_argument("--decisions", type=int, default=300, help="awaited audit rows per backend")
    p.add_argument("--writers", type=int, default=2, help="instances writing the shared store")
    p.add_argument("--messages", type=int, default=5000, help="broker messages")
    p.add_argument("--tracks-per-msg", type=int, default=50, help="tracks per traffic message")
    p.add_argument("--exchange-runs", type=int, default=200, help="region messages timed")


def _track(i: int, t_s: float) -> Any:
    from gcs_utm.model import OperationId, Track, TrackId

    return Track(
        id=TrackId(f"sysid:{i}@10.0.0.1:14550"),
        t_s=t_s,
        lat_deg=45.46 + i * 1e-5,
        lon_deg=-73.75,
        alt_amsl_m=100.0,
        east_m=float(i),
        north_m=0.0,
        vel_enu_mps=(5.0, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=OperationId(f"OP{i}"),
    )


def _store_records(
    location: str | Path, backend: str, args: argparse.Namespace
) -> list[dict[str, object]]:
    from gcs_utm.model import AuditEntry
    from gcs_utm.store import StoreConfig, StoreWriter

    writer = StoreWriter(location, StoreConfig(queue_size=max(10_000, args.batches * 2)))
    try:
        batches = [[_track(i, float(b)) for i in range(args.tracks)] for b in range(args.batches)]
        writer.write_tracks(batches[0])
        writer.flush(60)  # warm-up: the first upserts insert, the rest update
        t0 = time.perf_counter()
        for batch in batches[1:]:
            assert writer.write_tracks(batch) is not None
        writer.flush(600)
        tracks_ms = (time.perf_counter() - t0) * 1000.0
        t0 = time.perf_counter()
        for i in range(args.decisions):
            writer.audit(AuditEntry(t_s=float(i), actor="bench", action="x", subject="s")).result(
                60
            )
        decisions_ms = (time.perf_counter() - t0) * 1000.0
    finally:
        writer.close()
    n_tracks = args.tracks * (args.batches - 1)
    return [
        summary(
            "cluster.store_tracks",
            n_tracks,
            [tracks_ms],
            items_per_run=n_tracks,
            backend=backend,
            tracks_per_batch=args.tracks,
        ),
        summary(
            "cluster.store_decisions",
            args.decisions,
            [decisions_ms],
            items_per_run=args.decisions,
            backend=backend,
            note="each audit row awaited before the next",
        ),
    ]


def _shared_store_record(url: str, args: argparse.Namespace) -> dict[str, object]:
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _WRITER, url, str(k), str(args.tracks), str(args.batches)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for k in range(args.writers)
    ]
    try:
        for p in procs:
            assert p.stdout is not None and p.stdout.readline().strip() == "ready"
        for p in procs:  # all start together
            assert p.stdin is not None
            p.stdin.write("go\n")
            p.stdin.flush()
        elapsed_s = [float(p.stdout.readline()) for p in procs if p.stdout is not None]
        for p in procs:
            p.wait(60)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(10)
    n = args.writers * args.tracks * (args.batches - 1)
    return summary(
        "cluster.store_tracks_shared",
        n,
        [max(elapsed_s) * 1000.0],
        items_per_run=n,
        backend="postgresql",
        writers=args.writers,
        tracks_per_batch=args.tracks,
        per_writer_s=[round(e, 3) for e in elapsed_s],
    )


async def _failover_once(url: str, args: argparse.Namespace, epoch: int) -> float:
    from gcs_utm.cluster.config import ClusterConfig
    from gcs_utm.cluster.member import ClusterMember

    child = subprocess.Popen(
        [sys.executable, "-c", _OWNER, url, str(args.lease_s), str(args.renew_s), str(epoch)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    gained: dict[str, float] = {}

    async def on_gained(region: str, _lease: object) -> None:
        gained[region] = time.monotonic()

    async def on_lost(region: str, _lease: object) -> None:
        pass

    cfg = ClusterConfig(
        instance="standby",
        region="c1r0",
        standby=True,
        columns=2,
        rows=1,
        lease_s=args.lease_s,
        renew_s=args.renew_s,
    )
    member = ClusterMember(
        url, cfg, instance="standby", epoch=epoch + 1, on_gained=on_gained, on_lost=on_lost
    )
    task: asyncio.Task[None] | None = None
    try:
        line = await asyncio.wait_for(asyncio.to_thread(child.stdout.readline), 30.0)
        if line.split() != ["gained", "c0r0"]:
            raise RuntimeError(f"owner process did not take its region: {line!r}")
        await member.start()
        task = asyncio.create_task(member.run())
        await asyncio.sleep(args.lease_s)  # steady state: the owner renews, the standby waits
        killed = time.monotonic()
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        while "c0r0" not in gained and time.monotonic() - killed < 10 * args.lease_s:
            await asyncio.sleep(0.01)
        if "c0r0" not in gained:
            raise RuntimeError("the standby did not take the region over")
        return (gained["c0r0"] - killed) * 1000.0
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(10)
        child.stdout.close()
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        await member.close()


def _failover_record(url: str, args: argparse.Namespace) -> dict[str, object]:
    from gcs_utm.store import leases, open_store

    times: list[float] = []
    for run in range(args.runs):
        with open_store(url) as s:
            leases.clear(s)  # each run starts with no owner
        times.append(asyncio.run(_failover_once(url, args, 1000 + 2 * run)))
    return summary(
        "cluster.failover",
        args.runs,
        times,
        lease_s=args.lease_s,
        renew_s=args.renew_s,
        bound_ms=(args.lease_s + args.renew_s) * 1000.0,
    )


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _broker_rate(port: int, args: argparse.Namespace) -> tuple[float, int, int]:
    import aiomqtt

    from adapters.mqtt.encode import encode_traffic

    payload = encode_traffic([_track(i, 1.0) for i in range(args.tracks_per_msg)], 1.0)
    topic = "gcs_utm/cluster/regions/c0r0/traffic"
    got = 0
    async with (
        aiomqtt.Client("127.0.0.1", port, identifier="bench-sub") as sub,
        aiomqtt.Client("127.0.0.1", port, identifier="bench-pub") as pub,
    ):
        await sub.subscribe(topic, qos=0)
        await asyncio.sleep(0.2)
        done = asyncio.Event()

        async def receive() -> None:
            nonlocal got
            async for _msg in sub.messages:
                got += 1
                if got >= args.messages:
                    done.set()
                    return

        reader = asyncio.create_task(receive())
        t0 = time.perf_counter()
        for _ in range(args.messages):
            await pub.publish(topic, payload, qos=0)
        with contextlib.suppress(TimeoutError):  # a lost message shows in "received"
            await asyncio.wait_for(done.wait(), 60.0)
        elapsed_s = time.perf_counter() - t0
        reader.cancel()
        await asyncio.gather(reader, return_exceptions=True)
    return elapsed_s, got, len(payload)


@contextlib.contextmanager
def _mosquitto() -> Iterator[int | None]:
    """A loopback mosquitto for the run (its port), or None when it is not installed."""
    binary = shutil.which("mosquitto") or (
        "/usr/sbin/mosquitto" if os.path.exists("/usr/sbin/mosquitto") else None
    )
    if binary is None:
        yield None
        return
    port = _free_port()
    with tempfile.TemporaryDirectory() as d:
        conf = Path(d) / "m.conf"
        conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\n")
        proc = subprocess.Popen(
            [binary, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        try:
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline:
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                    break
                except OSError:
                    time.sleep(0.05)
            yield port
        finally:
            proc.terminate()
            proc.wait(10)


def _broker_record(port: int, args: argparse.Namespace) -> dict[str, object]:
    elapsed_s, got, size = asyncio.run(_broker_rate(port, args))
    return summary(
        "cluster.broker",
        args.messages,
        [elapsed_s * 1000.0],
        items_per_run=got,
        received=got,
        bytes_per_msg=size,
        tracks_per_msg=args.tracks_per_msg,
        tracks_per_s=round(got * args.tracks_per_msg / elapsed_s, 1),
    )


async def _exchange_latencies(port: int, args: argparse.Namespace) -> list[float]:
    """Instance A publishes its tracks near the border (region c0r0); instance B, owner of
    c1r0, receives them through its halo subscription: wall time from A's publish call to
    B's callback, per message."""
    from dataclasses import replace

    from adapters.mqtt.config import MqttConfig
    from gcs_utm.cluster.config import ClusterConfig
    from gcs_utm.cluster.exchange import RegionExchange, RemoteTrack
    from gcs_utm.cluster.member import region_map_of

    region_map = region_map_of(ClusterConfig(columns=2, rows=1))
    mqtt = MqttConfig(host="127.0.0.1", port=port)
    got: list[float] = []

    async def on_b(tracks: list[RemoteTrack]) -> None:
        got.append((time.time() - tracks[0].t_s) * 1000.0)

    async def on_a(tracks: list[RemoteTrack]) -> None:
        pass

    a = RegionExchange(mqtt, region_map, client_id="bench-a", on_tracks=on_a)
    b = RegionExchange(mqtt, region_map, client_id="bench-b", on_tracks=on_b)
    a.watch(["c0r0"])
    b.watch(["c1r0"])
    tasks = [asyncio.create_task(a.run()), asyncio.create_task(b.run())]
    try:
        await asyncio.wait_for(asyncio.gather(a.connected.wait(), b.connected.wait()), 10.0)
        await asyncio.sleep(0.5)  # subscriptions in place
        tracks = [replace(_track(i, 0.0), east_m=-100.0 - i) for i in range(args.tracks_per_msg)]
        for _ in range(args.exchange_runs):
            now = time.time()
            a.publish([replace(t, t_s=now) for t in tracks], now)
            await asyncio.sleep(0.05)
        deadline = time.monotonic() + 5.0
        while len(got) < args.exchange_runs and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
    finally:
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return got


def _exchange_record(port: int, args: argparse.Namespace) -> dict[str, object]:
    latencies = asyncio.run(_exchange_latencies(port, args))
    if not latencies:
        raise RuntimeError("no traffic message crossed the region border")
    return summary(
        "cluster.exchange",
        args.exchange_runs,
        latencies,
        received=len(latencies),
        tracks_per_msg=args.tracks_per_msg,
        note="publish call in one instance to the neighbour's callback, loopback broker; "
        "detection adds up to one publication period (0.5 s) and one monitoring period",
    )


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    url = args.url
    if not url:
        raise SystemExit(
            "gcs-utm bench cluster: pass --url postgresql://... (a database it may fill); "
            "from a checkout, python -m tests.store.pgserver starts a private one"
        )
    records = [_failover_record(url, args)]
    with tempfile.TemporaryDirectory() as d:
        records += _store_records(Path(d) / "bench.sqlite3", "sqlite", args)
    records += _store_records(url, "postgresql", args)
    if args.writers > 1:
        records.append(_shared_store_record(url, args))
    with _mosquitto() as port:
        if port is not None:
            records.append(_broker_record(port, args))
            records.append(_exchange_record(port, args))
    return records
