"""The dense profile of ``gcs-utm bench strategic``: ``gcs-utm scenario check`` of the dense
airspace (:mod:`.dense_airspace`) end to end, as a user runs it, and its stages.

Records, per N (``--dense-plans``):
- ``strategic.scenario_check``: the command ``python -m gcs_utm scenario check FILE --json``
  in a fresh process (in the file's folder), stdout to a file: wall time (median of
  ``--cli-runs``, after one warm-up run) and the child's CPU time (user + system, median),
  the conflicts it wrote;
- ``strategic.dense_stages``: the same work in this process, stage by stage (median of
  ``--runs``): ``load_ms`` (``load_any``) and ``check_ms`` (``strategic_check``, the core
  call), with the conflicts per plan; ``median_ms`` is their sum (the report is written by
  the command, a layer above the benchmarks: it is in ``strategic.scenario_check`` only);
- with ``--against DIR`` (another checkout of gcs-utm, e.g. the code before a change):
  ``strategic.scenario_check_against``, the same command with ``PYTHONPATH=DIR``, run
  alternately with ours so that both see the same machine load, and ``same_report``: whether
  both wrote the same JSON document.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from gcs_utm.bench.dense_airspace import write_dense_scenario
from gcs_utm.bench.timing import summary, time_runs


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--dense-plans", type=int, action="append", help="N of the dense profile (repeatable)"
    )
    p.add_argument("--cli-runs", type=int, default=5, help="end-to-end runs per N")
    p.add_argument("--against", help="another gcs-utm checkout to time side by side")


def _run_cli(path: Path, out: Path, pythonpath: str | None) -> tuple[float, float]:
    """Wall and CPU ms of one ``scenario check --json`` process."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    cmd = [sys.executable, "-m", "gcs_utm", "scenario", "check", str(path), "--json"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with out.open("wb") as fh:  # run in the file's folder: the current one may hold a checkout
        subprocess.run(cmd, stdout=fh, env=env, cwd=path.parent, check=True, timeout=900)
    wall_ms = (time.perf_counter() - t0) * 1000.0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall_ms, cpu_s * 1000.0


def _cli_record(name: str, n: int, runs: list[tuple[float, float]], out: Path) -> dict[str, object]:
    conflicts = len(json.loads(out.read_text())["conflicts"])
    cpu = [c for _, c in runs]
    return summary(
        name,
        n,
        [w for w, _ in runs],
        cpu_median_ms=round(statistics.median(cpu), 1),
        conflicts=conflicts,
        conflicts_per_plan=round(conflicts / n, 2),
    )


def _stages(path: Path, n: int, runs: int) -> dict[str, object]:
    from gcs_utm.core.monitoring import MonitoringConfig, strategic_check
    from gcs_utm.scenario import load_any

    box: dict[str, object] = {}

    def load() -> None:
        box["scenario"] = load_any(path)

    def check() -> None:
        sc = box["scenario"]
        box["report"] = strategic_check(sc.operations, sc.geofences, sc.frame, MonitoringConfig())  # type: ignore[attr-defined]

    medians = {}
    for stage, fn in (("load_ms", load), ("check_ms", check)):
        medians[stage] = round(statistics.median(time_runs(fn, runs=runs)), 1)
    conflicts = len(box["report"].conflicts)  # type: ignore[attr-defined]
    ms = [sum(medians.values())]  # the record's median: the sum of the stages' medians
    return summary(
        "strategic.dense_stages",
        n,
        ms,
        stage_runs=runs,
        **medians,
        conflicts=conflicts,
        conflicts_per_plan=round(conflicts / n, 2),
    )


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    records: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory(prefix="gcs-utm-bench-") as tmp:
        for n in args.dense_plans or [2000, 10000]:
            path = write_dense_scenario(Path(tmp) / f"dense_{n}.toml", n, args.seed)
            ours: list[tuple[float, float]] = []
            theirs: list[tuple[float, float]] = []
            out_ours, out_theirs = Path(tmp) / "ours.json", Path(tmp) / "theirs.json"
            _run_cli(path, out_ours, None)  # warm-up (file cache, bytecode)
            for _ in range(args.cli_runs):
                ours.append(_run_cli(path, out_ours, None))
                if args.against:
                    theirs.append(_run_cli(path, out_theirs, args.against))
            records.append(_cli_record("strategic.scenario_check", n, ours, out_ours))
            if args.against:
                rec = _cli_record("strategic.scenario_check_against", n, theirs, out_theirs)
                rec["against"] = args.against
                rec["same_report"] = json.loads(out_ours.read_text()) == json.loads(
                    out_theirs.read_text()
                )
                records.append(rec)
            records.append(_stages(path, n, args.runs))
    return records
