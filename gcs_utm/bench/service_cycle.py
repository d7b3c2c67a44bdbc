"""The monitoring service's cycle in CPU time and wall time, with the page faults it costs.

The cycle is ``monitoring.service_cycle`` of ``gcs-utm bench monitoring`` (what
``MonitoringService.run_once`` does: ``Tracker.snapshot`` -> ``AirspaceSnapshot`` ->
``Monitor.cycle``, steady state, the threats persisting), on the same traffic (the same
seed and draws, so ``--uas 10000 --uas 100000`` here is the airspace of ``bench monitoring
--uas 10000 --uas 100000 --density-of 10000``). Wall time on a shared machine is mostly the
other jobs' load; CPU time of the process (``getrusage``, user + system) is much less
disturbed, so each cycle is timed in both, and the minor page faults (fresh memory mapped
and zeroed by the kernel, counted in system time) are reported with them. The process keeps
the memory it frees, as the service does (``gcs_utm.app.memory``, set by the service's
entry point); ``--default-allocator`` times the C library's default behaviour instead.

Records:
- ``service_cycle``: per N, medians over ``--runs`` cycles after ``--warmup`` untimed ones of
  wall (``median_ms``), CPU (``cpu_median_ms``), user and system time, minor page faults;
  the threats open, the load average before and after.
- ``service_cycle.scaling``: between the smallest and the largest N, the growth of the CPU
  and wall medians (ratio and fitted exponent; 1.0 is linear).
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import statistics
import time

import numpy as np

from gcs_utm.app.memory import retain_freed_memory
from gcs_utm.bench.monitoring import BOX_M, _fences, _Setup

NAME = "service_cycle"
IN_ALL = False  # the 100,000-UAS airspace takes about half a minute: run when named


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--uas", "--n", type=int, action="append", help="N (repeatable)")
    p.add_argument("--runs", type=int, default=7, help="timed cycles per N")
    p.add_argument(
        "--warmup",
        type=int,
        default=3,
        help="untimed cycles before them (the heap grows in the first)",
    )
    p.add_argument("--seed", type=int, default=7)
    p.add_argument(
        "--density-of",
        type=int,
        default=10000,
        metavar="N0",
        help="traffic density of N0 UAS in the 50 km box (the box side grows with "
        "sqrt(N / N0), the geofences with N / N0); 0: one 50 km box for every N",
    )
    p.add_argument(
        "--default-allocator",
        action="store_true",
        help="leave the C allocator's defaults (the service keeps the memory it frees)",
    )


def _timed(fn: object, runs: int, warmup: int) -> dict[str, list[float]]:
    """Wall, CPU, user, system (ms) and minor faults of each of ``runs`` calls of ``fn``."""
    assert callable(fn)
    for _ in range(warmup):
        fn()
    out: dict[str, list[float]] = {"wall": [], "cpu": [], "user": [], "sys": [], "faults": []}
    for _ in range(runs):
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        fn()
        t1 = time.perf_counter()
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        user_ms = (r1.ru_utime - r0.ru_utime) * 1000.0
        sys_ms = (r1.ru_stime - r0.ru_stime) * 1000.0
        out["wall"].append((t1 - t0) * 1000.0)
        out["cpu"].append(user_ms + sys_ms)
        out["user"].append(user_ms)
        out["sys"].append(sys_ms)
        out["faults"].append(float(r1.ru_minflt - r0.ru_minflt))
    return out


def _growth(medians: dict[int, float]) -> dict[str, float]:
    lo, hi = min(medians), max(medians)
    ns = np.array(sorted(medians), dtype=float)
    ts = np.array([medians[int(k)] for k in ns])
    return {
        "ratio": round(medians[hi] / medians[lo], 2),
        "fitted_exponent": round(float(np.polyfit(np.log(ns), np.log(ts), 1)[0]), 3),
    }


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    if args.runs < 1 or args.warmup < 0:
        raise ValueError("--runs must be >= 1 and --warmup >= 0")
    retained = False if args.default_allocator else retain_freed_memory()
    sizes = args.uas or [10000, 100000]
    rng = np.random.default_rng(args.seed)
    base_fences = _fences(rng)  # the draws of bench monitoring, in its order
    n0 = args.density_of
    records: list[dict[str, object]] = []
    cpu: dict[int, float] = {}
    wall: dict[int, float] = {}
    for n in sizes:
        box_m = BOX_M * math.sqrt(n / n0) if n0 and n > n0 else BOX_M
        fences = base_fences
        if box_m != BOX_M:
            fences = _fences(rng, box_m, round(100 * box_m**2 / BOX_M**2))
        s = _Setup(n, fences, rng, box_m)
        s.prepare_service()
        load_before = os.getloadavg()[0]
        t = _timed(s.service_cycle, args.runs, args.warmup)
        med = {k: statistics.median(v) for k, v in t.items()}
        cpu[n], wall[n] = med["cpu"], med["wall"]
        records.append(
            {
                "benchmark": "service_cycle",
                "n": n,
                "runs": args.runs,
                "median_ms": round(med["wall"], 2),
                "min_ms": round(min(t["wall"]), 2),
                "max_ms": round(max(t["wall"]), 2),
                "cpu_median_ms": round(med["cpu"], 2),
                "cpu_min_ms": round(min(t["cpu"]), 2),
                "cpu_max_ms": round(max(t["cpu"]), 2),
                "user_median_ms": round(med["user"], 2),
                "sys_median_ms": round(med["sys"], 2),
                "minor_faults_median": int(med["faults"]),
                "threats": s.monitor.open_count(),
                "box_km": round(box_m / 1000.0, 1),
                "geofences": len(fences),
                "retain_freed_memory": retained,
                "loadavg_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
            }
        )
        del s
    if len(cpu) >= 2:
        records.append(
            {
                "benchmark": "service_cycle.scaling",
                "n": [min(cpu), max(cpu)],
                "cpu": _growth(cpu),
                "wall": _growth(wall),
            }
        )
    return records
