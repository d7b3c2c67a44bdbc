"""A fast-time run (``gcs-utm run --speed max``, each run of ``gcs-utm eval``) decides the
same whatever the machine: its report (``Report.comparable``: wall-clock fields and loopback
port numbers aside) depends on the scenario file only, not on how fast the wall clock runs
beside the simulation (a loaded machine) nor on the process's string hash seed
(``PYTHONHASHSEED``: ``eval --jobs N`` runs each file in a process of its own).

tests/data/eval/hash_order.toml (seed 4's enc_4_0127): at t = 56 s three accepted plans, two
of them for UAS1, are re-checked before their upload in one cycle; which of UAS1's two plans
the re-check took as UAS1's came from a set's hash order, and the file flew 1 or 3 losses.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings

SCENARIO = Path(__file__).resolve().parents[1] / "data" / "eval" / "hash_order.toml"
pytestmark = [pytest.mark.network, pytest.mark.timeout(300)]

DURATION_S = 90.0  # the re-checks at t = 56 s and the plans and holds that follow

_RUN = """
import json, math, sys
from pathlib import Path
from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings
options = RunOptions(speed=math.inf, headless=True, quiet=True, figures=False,
    operator=OperatorMode.AUTO_ACCEPT, out_dir=Path(sys.argv[2]), duration_s=float(sys.argv[3]))
report = run_scenario_blocking(Path(sys.argv[1]), Settings(), options)
print(json.dumps(report.comparable(), sort_keys=True))
"""


def _options(out: Path) -> RunOptions:
    return RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=out,
        figures=False,
        duration_s=DURATION_S,
    )


def _run(out: Path) -> str:
    report = run_scenario_blocking(SCENARIO, Settings(), _options(out))
    assert any(r.verified for r in report.recommendations)  # the run resolved something
    return json.dumps(report.comparable(), sort_keys=True)


def test_a_fast_time_run_does_not_depend_on_the_wall_clock(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A wall clock running 1000 times faster (as if every step of the run were that much
    slower: a loaded machine) changes nothing a fast-time run decides or reports: every
    timer of the run (upload deadlines and waits, the vehicles' mission-protocol timers) is
    on the simulated clock."""
    quiet = _run(tmp_path / "quiet")
    real = time.monotonic
    t0 = real()
    monkeypatch.setattr(time, "monotonic", lambda: t0 + 1000.0 * (real() - t0))
    loaded = _run(tmp_path / "loaded")
    assert loaded == quiet


def _runs_with_hash_seeds(seeds: tuple[int, ...], out: Path) -> list[str]:
    """The comparable report of one run per hash seed, each in a process of its own (started
    together: the runs are independent)."""
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _RUN, str(SCENARIO), str(out / f"seed{s}"), str(DURATION_S)],
            env={**os.environ, "PYTHONHASHSEED": str(s)},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for s in seeds
    ]
    reports = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=280)
        assert p.returncode == 0, stderr[-2000:]
        reports.append(stdout)
    return reports


def test_a_fast_time_run_does_not_depend_on_the_hash_seed(tmp_path: Path) -> None:
    """Two processes with different string hash seeds (as two ``eval`` workers) give one
    report: no decision follows a set's or a dict's hash order."""
    first, second = _runs_with_hash_seeds((0, 1), tmp_path)
    assert json.loads(first)["recommendations"]  # the run decided something
    assert first == second
