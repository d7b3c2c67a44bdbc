"""A neighbour whose vehicle is not heard yet is not re-planned (``deconfliction.unheard``;
issue 30, class 2: escalations without a proposed command). In the CI set's
enc_7_0009_late_near_threshold (tests/data/eval/unheard_neighbour.toml) a loss between UAS1
and UAS4 predicted at 44 s drew UAS2 into the joint selection, filed to fly from 94 s and
not heard yet: its plan failed to upload twice, its safe command (hold) was not
acknowledged, and EM escalated with nothing to propose."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings

DATA = Path(__file__).resolve().parents[1] / "data" / "eval"

pytestmark = [pytest.mark.network, pytest.mark.timeout(300)]


def test_a_uas_not_heard_yet_gets_no_plan_and_no_escalation_lacks_a_command(
    tmp_path: Path,
) -> None:
    options = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        figures=False,
    )
    report = run_scenario_blocking(DATA / "unheard_neighbour.toml", Settings(), options)
    los = [r for r in report.recommendations if "LOS" in r.threat]
    assert los and {r.uas for r in los} <= {"UAS1", "UAS4"}, [(r.id, r.state) for r in los]
    assert all(r.state == "applied" for r in los), [(r.id, r.state) for r in los]
    assert not report.escalations, report.escalations
