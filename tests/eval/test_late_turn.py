"""A late encounter flown in closed loop (issue 30, class 2): a multirotor appears 4.6 s
before a loss with a fixed wing coming head-on (tests/data/eval/late_head_on.toml, seed 2's
enc_2_0001, fast time, every recommendation accepted after the automatic operator's 2 s).
Holding the multirotor, the best command without a turn, the two passed 29 m apart against
50 m; the fixed wing told to turn away passes 77 m from it (docs/emergency.md, "Which
command")."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings

DATA = Path(__file__).resolve().parents[1] / "data" / "eval"

pytestmark = [pytest.mark.network, pytest.mark.timeout(300)]


def test_the_fixed_wing_turns_away_and_the_minima_are_kept(tmp_path: Path) -> None:
    options = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        figures=False,
    )
    report = run_scenario_blocking(DATA / "late_head_on.toml", Settings(), options)
    assert report.truth is not None
    (pair,) = report.truth.pairs
    assert not pair.loss_of_separation, pair
    assert pair.min_ratio is not None and pair.min_ratio > 1.2, pair
    (esc,) = [e for e in report.escalations if "LOS" in e.text]
    assert "sooner than a new plan can start" in esc.text, esc
    assert re.search(r"turn (left|right) towards a point far abeam, [^;]* for UAS1", esc.text), esc
