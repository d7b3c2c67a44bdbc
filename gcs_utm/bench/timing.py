"""Repeat-and-median timing shared by all benchmarks. The machine is shared and noisy, so every
figure is a median over ``runs`` repetitions after ``warmup`` untimed ones."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def time_runs(fn: Callable[[], object], *, runs: int, warmup: int = 1) -> list[float]:
    """Call ``fn`` ``warmup`` + ``runs`` times; return the timed durations in milliseconds."""
    if runs < 1:
        raise ValueError("runs must be >= 1")
    for _ in range(warmup):
        fn()
    out: list[float] = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1000.0)
    return out


def summary(
    benchmark: str,
    n: int,
    durations_ms: list[float],
    *,
    items_per_run: float | None = None,
    **extra: object,
) -> dict[str, object]:
    """The benchmark record of the output convention (median/min/max ms, per_s if a
    throughput: ``items_per_run`` items are processed in one run)."""
    med = statistics.median(durations_ms)
    record: dict[str, object] = {
        "benchmark": benchmark,
        "n": n,
        "runs": len(durations_ms),
        "median_ms": round(med, 4),
        "min_ms": round(min(durations_ms), 4),
        "max_ms": round(max(durations_ms), 4),
    }
    if len(durations_ms) >= 2:
        q = statistics.quantiles(durations_ms, n=100, method="inclusive")
        record["p99_ms"] = round(q[98], 4)
    if items_per_run is not None and med > 0:
        record["per_s"] = round(items_per_run / (med / 1000.0), 1)
    record.update(extra)
    return record
