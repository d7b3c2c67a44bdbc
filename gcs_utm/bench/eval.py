"""Closed-loop evaluation speed: encounters per minute of ``gcs-utm eval`` over a fixed
generated set (``--n`` encounters of ``--seed``, ``--profile``; default 40 of seed 6, every
profile), run ``--repeats`` times, the median quoted. Also the CPU seconds per encounter
(this process and its workers), less sensitive to other jobs on the machine than the wall
time. The reports are the evaluation's (deterministic: the same on every repeat).

Not part of ``gcs-utm bench`` without a name (minutes): ``gcs-utm bench eval --json``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

NAME = "eval"
IN_ALL = False  # minutes, not seconds: only when asked for by name


def add_arguments(p: argparse.ArgumentParser) -> None:
    from gcs_utm.eval.generator import PROFILES

    p.add_argument("--n", type=int, default=40, help="encounters (default 40)")
    p.add_argument("--seed", type=int, default=6, help="seed of the encounter set (default 6)")
    p.add_argument(
        "--profile", choices=(*PROFILES, "all"), default="all", help="generator profile (all)"
    )
    p.add_argument("--jobs", type=int, default=1, help="runs at once (default 1)")
    p.add_argument("--repeats", type=int, default=3, help="runs of the whole set (default 3)")


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished children (the eval's workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    from gcs_utm.eval.generator import write_encounters
    from gcs_utm.eval.run import EvalOptions, run_eval
    from gcs_utm.settings import Settings

    if args.n < 1 or args.repeats < 1 or args.jobs < 1:
        raise ValueError(
            f"bench eval: --n, --repeats and --jobs must be >= 1, got "
            f"{args.n}, {args.repeats}, {args.jobs}"
        )
    per_minute: list[float] = []
    cpu_per_encounter_s: list[float] = []
    failed = 0
    with tempfile.TemporaryDirectory(prefix="gcs-utm-bench-eval-") as tmp:
        paths = write_encounters(Path(tmp) / "scenarios", args.n, args.seed, args.profile)
        for k in range(args.repeats):
            out = Path(tmp) / f"run{k}"
            cpu0, wall0 = _cpu_s(), time.perf_counter()
            s = run_eval(paths, Settings(), EvalOptions(out_dir=out, jobs=args.jobs))
            wall_s, cpu_s = time.perf_counter() - wall0, _cpu_s() - cpu0
            per_minute.append(60.0 * args.n / wall_s)
            cpu_per_encounter_s.append(cpu_s / args.n)
            failed = max(failed, s.totals.failed_runs)
    return [
        {
            "benchmark": "eval",
            "n": args.n,
            "seed": args.seed,
            "profile": args.profile,
            "jobs": args.jobs,
            "runs": args.repeats,
            "cpus": os.cpu_count(),
            "failed_runs": failed,
            "encounters_per_minute": round(statistics.median(per_minute), 2),
            "encounters_per_minute_all": [round(v, 2) for v in per_minute],
            "cpu_s_per_encounter": round(statistics.median(cpu_per_encounter_s), 3),
            "cpu_s_per_encounter_all": [round(v, 3) for v in cpu_per_encounter_s],
        }
    ]
