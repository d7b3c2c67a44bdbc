"""Soak: serve's services through many simulated hours in fast time; memory per hour.

``gcs-utm bench soak --hours 24 --json`` builds the service as ``serve`` does
(:func:`gcs_utm.app.build_runtime`, automatic operator, SQLite store, the service tasks) on
a fast-time loop, and plays traffic at it as an operator's MQTT client would: an operation
filed every ``--every-s`` simulated seconds, started, its vehicle reporting its position once
a second along its current plan (so an accepted resolution is flown), then ended. Every
``--conflict-every``-th operation is filed head-on into the one before it, at the same
height, so Monitoring raises threats and EM/TD decide. At the end of each simulated hour
(after a full garbage collection) one record: RSS, the store's rows and bytes, the
interpreter's objects by type (the types that grew most since the first record), tasks, open
file descriptors and sockets, and what the airspace holds. The last record sums up: the
RSS growth after the first hour and the wall and CPU time of the whole run.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import math
import os
import resource
import sys
import tempfile
import time
from collections import Counter, deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

NAME = "soak"
IN_ALL = False  # minutes of wall time: runs only when named

HOUR_S = 3600.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hours", type=float, default=24.0, help="simulated hours (default 24)")
    p.add_argument(
        "--every-s", type=float, default=60.0, help="simulated s between two filed operations"
    )
    p.add_argument("--flight-s", type=float, default=600.0, help="simulated s each operation flies")
    p.add_argument(
        "--conflict-every",
        type=int,
        default=4,
        help="every n-th operation flies head-on into the one before it (0: none)",
    )
    p.add_argument("--top", type=int, default=8, help="object types listed per hour")
    p.add_argument(
        "--sample-s", type=float, default=HOUR_S, help="simulated s between records (an hour)"
    )
    p.add_argument(
        "--keep-s",
        type=float,
        default=None,
        help="retention of ended operations (default: the service's, services/retention.py)",
    )
    p.add_argument(
        "--store-dir", type=Path, default=None, help="folder of the SQLite store (default: temp)"
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class Traffic:
    """What the soak plays at the service."""

    hours: float = 24.0
    every_s: float = 60.0
    flight_s: float = 600.0
    conflict_every: int = 4
    top: int = 8
    sample_s: float = HOUR_S
    keep_s: float | None = None

    def __post_init__(self) -> None:
        if not min(self.hours, self.every_s, self.flight_s, self.sample_s) > 0:
            raise ValueError("soak: --hours, --every-s, --flight-s and --sample-s must be > 0")
        if self.keep_s is not None and not self.keep_s >= 0:
            raise ValueError("soak: --keep-s must be >= 0")
        if self.conflict_every < 0:
            raise ValueError("soak: --conflict-every must be >= 0")


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    from gcs_utm.app import configure_interpreter

    traffic = Traffic(
        hours=args.hours,
        every_s=args.every_s,
        flight_s=args.flight_s,
        conflict_every=args.conflict_every,
        top=args.top,
        sample_s=args.sample_s,
        keep_s=args.keep_s,
    )
    configure_interpreter()  # as serve: the allocator keeps freed memory (app/memory.py)
    if args.store_dir is not None:
        args.store_dir.mkdir(parents=True, exist_ok=True)
        return soak(traffic, args.store_dir / "soak.sqlite")
    with tempfile.TemporaryDirectory(prefix="gcs-utm-soak-") as tmp:
        return soak(traffic, Path(tmp) / "soak.sqlite")


def soak(traffic: Traffic, db_path: Path) -> list[dict[str, Any]]:
    """Run the soak on a fast-time loop of its own; the hourly records and the summary."""
    from gcs_utm.clock import FastTimeLoop

    for suffix in ("", "-wal", "-shm"):
        Path(str(db_path) + suffix).unlink(missing_ok=True)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with asyncio.Runner(loop_factory=FastTimeLoop) as runner:
        records = runner.run(_soak(traffic, db_path))
    records.append(_summary(records, time.perf_counter() - wall0, time.process_time() - cpu0))
    return records


async def _soak(traffic: Traffic, db_path: Path) -> list[dict[str, Any]]:
    from gcs_utm.app import FAST_TIME_EPOCH_UTC_S
    from gcs_utm.app.wiring import (
        FrontendOptions,
        OperatorMode,
        Persistence,
        attach_frontends,
        build_runtime,
        start_service_tasks,
    )
    from gcs_utm.clock import LoopClock
    from gcs_utm.geo import LocalFrame
    from gcs_utm.settings import Settings
    from gcs_utm.store import StoreWriter

    from ._soak_traffic import play_traffic

    settings = Settings()
    clock = LoopClock(asyncio.get_running_loop(), FAST_TIME_EPOCH_UTC_S)
    frame = LocalFrame(origin_lat_deg=47.0, origin_lon_deg=8.0, ground_elevation_amsl_m=400.0)
    store = Persistence(StoreWriter(db_path, settings.store))
    rt = build_runtime(settings, clock, frame, store)
    frontends = attach_frontends(
        rt, FrontendOptions(operator=OperatorMode.AUTO_ACCEPT, headless=True, quiet=True)
    )
    if traffic.keep_s is not None and rt.retention is not None:
        rt.retention.keep_s = traffic.keep_s
    records: list[dict[str, Any]] = []
    baseline: Counter[str] = Counter()
    t0_s = clock.now_s()
    try:
        async with asyncio.TaskGroup() as tg:
            tasks = start_service_tasks(tg, rt, frontends)
            tasks.append(
                tg.create_task(
                    play_traffic(
                        rt,
                        every_s=traffic.every_s,
                        flight_s=traffic.flight_s,
                        conflict_every=traffic.conflict_every,
                    ),
                    name="soak-traffic",
                )
            )
            total_s = traffic.hours * HOUR_S
            for k in range(1, math.ceil(total_s / traffic.sample_s - 1e-9) + 1):
                end_s = t0_s + min(k * traffic.sample_s, total_s)
                await clock.sleep(end_s - clock.now_s())
                await _settle_store(rt)
                hour = round((clock.now_s() - t0_s) / HOUR_S, 3)
                rec = _measure(rt, hour, db_path, baseline, traffic.top)
                records.append(rec)
                print(_progress(rec), file=sys.stderr, flush=True)
            for t in tasks:
                t.cancel()
    finally:
        await rt.usm.drain()
        await rt.usm.close()
        await rt.hub.close()
        store.close()
    return records


async def _settle_store(rt: Any) -> None:
    """Let the store's writer thread catch up, so the row counts are the hour's."""
    await asyncio.to_thread(rt.store.writer.flush, 30.0)


def _measure(
    rt: Any, hour: float, db_path: Path, baseline: Counter[str], top: int
) -> dict[str, Any]:
    gc.collect()
    types = Counter(type(o).__name__ for o in gc.get_objects())
    if not baseline:
        baseline.update(types)
    grown = sorted(
        ((name, n - baseline.get(name, 0)) for name, n in types.items()),
        key=lambda kv: -kv[1],
    )[:top]
    ops = rt.airspace.operations
    return {
        "benchmark": "soak.hour",
        "hour": hour,
        "sim_t_s": round(rt.clock.now_s(), 1),
        "rss_mb": round(_rss_mb(), 2),
        "max_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 2),
        "cpu_s": round(time.process_time(), 2),
        "gc_objects": sum(types.values()),
        "objects_grown_since_first": dict(grown),
        "tasks": len(asyncio.all_tasks()),
        "fds": _fds()[0],
        "sockets": _fds()[1],
        "store": _store_size(db_path),
        "operations_held": len(ops),
        "tracks_held": len(rt.tracking.tracks_now()),
        "containers": _containers(rt),
    }


_PARTS = (
    "airspace",
    "usm",
    "tracking",
    "tracker",
    "monitoring",
    "emergency",
    "hub",
    "surveillance",
    "remote_id",
    "remote_id_ingest",
    "remote_id_tracks",
    "traffic_out",
    "filing",
)


def _containers(rt: Any) -> dict[str, int]:
    """Sizes of the containers the services hold (dicts, lists, sets, deques, one level into
    each part and its direct sub-parts): what grows with time shows here by name."""
    sizes: dict[str, int] = {}
    for name in _PARTS:
        part = getattr(rt, name)
        _sizes_of(part, name, sizes, depth=2)
    for name in ("plan_history", "geofence_history", "samples"):
        sizes[name] = len(getattr(rt, name))
    # TD's plan cache, deeper than the walk goes: the plans in use (core/deconfliction)
    sizes["td._plans"] = len(rt.emergency.em.td._plans)
    return {k: v for k, v in sorted(sizes.items()) if v > 0}


def _sizes_of(obj: Any, prefix: str, sizes: dict[str, int], depth: int) -> None:
    attrs = getattr(obj, "__dict__", None)
    if attrs is None:
        slots = getattr(type(obj), "__slots__", ())
        attrs = {s: getattr(obj, s, None) for s in slots}
    for key, value in attrs.items():
        if isinstance(value, (dict, list, set, frozenset, deque, tuple)):
            sizes[f"{prefix}.{key}"] = len(value)
        elif depth > 1 and type(value).__module__.startswith(("gcs_utm", "adapters")):
            _sizes_of(value, f"{prefix}.{key}", sizes, depth - 1)


def _progress(rec: dict[str, Any]) -> str:
    return (
        f"soak hour {rec['hour']}: rss {rec['rss_mb']} MB, {rec['gc_objects']} objects, "
        f"store {rec['store']['rows']} rows / {rec['store']['bytes'] / 1e6:.1f} MB, "
        f"cpu {rec['cpu_s']} s"
    )


def _rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _fds() -> tuple[int, int]:
    """(open file descriptors, of which sockets) of this process."""
    fd_dir = Path("/proc/self/fd")
    n = sockets = 0
    for entry in fd_dir.iterdir():
        try:
            target = os.readlink(entry)
        except OSError:
            continue
        n += 1
        sockets += target.startswith("socket:")
    return n, sockets


def _store_size(db_path: Path) -> dict[str, Any]:
    size_b = sum(
        Path(str(db_path) + s).stat().st_size
        for s in ("", "-wal")
        if Path(str(db_path) + s).exists()
    )
    from gcs_utm.store.sqlite import table_row_counts

    rows = table_row_counts(db_path)
    return {"bytes": size_b, "rows": sum(rows.values()), "rows_by_table": rows}


def _summary(records: list[dict[str, Any]], wall_s: float, cpu_s: float) -> dict[str, Any]:
    # growth is counted from the end of the first simulated hour (start-up and the first
    # operations' state are in place by then), or from the first record of a shorter soak
    first = next((r for r in records if r["hour"] >= 1.0), records[0])
    last = records[-1]
    return {
        "benchmark": "soak.summary",
        "hours": last["hour"],
        "from_hour": first["hour"],
        "rss_from_mb": first["rss_mb"],
        "rss_last_mb": last["rss_mb"],
        "rss_growth_after_first_hour_mb": round(last["rss_mb"] - first["rss_mb"], 2),
        "rss_max_mb": max(r["rss_mb"] for r in records),
        "gc_objects_growth_after_first_hour": last["gc_objects"] - first["gc_objects"],
        "store_bytes": last["store"]["bytes"],
        "store_rows": last["store"]["rows"],
        "wall_s": round(wall_s, 1),
        "cpu_s": round(cpu_s, 1),
        "loadavg_1min": round(os.getloadavg()[0], 2),
    }
