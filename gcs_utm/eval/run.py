"""Run scenarios end to end in fast time with an automatic operator, in parallel processes,
and write each report plus a summary (``summary.json``, ``summary.md``) into one folder.

Each scenario runs in a worker process of its own event loop (``run_scenario_blocking`` at
``speed = inf``): runs share nothing, so ``jobs`` only changes how long the whole set takes.
A run that raises is recorded as failed (its error in the summary), never silently dropped.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import multiprocessing
import os
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings

from .summary import EvalSummary, ScenarioOutcome, markdown, outcome, summarise

_log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class EvalOptions:
    """``out_dir``: reports go to ``out_dir/reports``, the summary to ``out_dir``;
    ``operator``: auto-accept (default) or auto-reject; ``jobs``: worker processes (default:
    this machine's CPUs)."""

    out_dir: Path
    jobs: int = dataclasses.field(default_factory=lambda: os.cpu_count() or 1)
    operator: str = OperatorMode.AUTO_ACCEPT
    keep_stores: bool = False

    def __post_init__(self) -> None:
        if self.jobs < 1:
            raise ValueError(f"EvalOptions.jobs: expected at least 1, got {self.jobs}")
        if self.operator not in (OperatorMode.AUTO_ACCEPT, OperatorMode.AUTO_REJECT):
            raise ValueError(
                f"EvalOptions.operator: expected auto-accept or auto-reject, got {self.operator!r}"
            )


def run_one(path: Path, settings: Settings, options: EvalOptions) -> ScenarioOutcome:
    """One scenario in fast time; its report is written, its outcome returned."""
    reports = options.out_dir / "reports"
    run = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=options.operator,
        out_dir=reports,
        figures=False,
    )
    try:
        report = run_scenario_blocking(path, settings, run)
    except Exception as exc:  # one broken scenario must not stop the set: recorded
        _log.exception("eval: %s failed", path)
        return ScenarioOutcome(scenario=path.stem, wall_clock_s=0.0, error=f"{exc!r}"[:300])
    if not options.keep_stores:
        for suffix in ("", "-wal", "-shm"):
            Path(str(reports / f"{report.scenario}.sqlite") + suffix).unlink(missing_ok=True)
    return outcome(report)


def _worker(args: tuple[str, Settings, EvalOptions]) -> ScenarioOutcome:
    path, settings, options = args
    logging.basicConfig(level=logging.ERROR)
    return run_one(Path(path), settings, options)


def run_eval(paths: Sequence[Path], settings: Settings, options: EvalOptions) -> EvalSummary:
    """Run every scenario, then write ``summary.json`` and ``summary.md``."""
    options.out_dir.mkdir(parents=True, exist_ok=True)
    work = [(str(p), settings, options) for p in paths]
    wall0 = time.perf_counter()
    if options.jobs == 1 or len(work) == 1:
        outcomes = [_worker(w) for w in work]
    else:
        # spawned workers: no inherited threads or loops from the parent
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=options.jobs, mp_context=ctx) as pool:
            outcomes = list(pool.map(_worker, work))
    summary = summarise(outcomes, elapsed_wall_s=time.perf_counter() - wall0, jobs=options.jobs)
    write_summary(summary, options.out_dir)
    return summary


def summary_json(summary: EvalSummary) -> dict[str, Any]:
    """The summary as JSON: the totals at the top level, then the rest (``profiles``: one
    object per profile with its totals; ``outcomes``: one per run)."""
    out = dataclasses.asdict(summary)
    out = {**out.pop("totals"), **out}
    for o, data in zip(summary.outcomes, out["outcomes"], strict=True):
        data["predicted"] = o.predicted
        data["avoided"] = o.avoided
        data["missed"] = o.missed
    return out


def write_summary(summary: EvalSummary, out_dir: Path) -> None:
    (out_dir / "summary.json").write_text(json.dumps(summary_json(summary), indent=1))
    (out_dir / "summary.md").write_text(markdown(summary))
