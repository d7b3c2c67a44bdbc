"""The evaluation's judge in closed loop: a vehicle is traffic from take-off to landing, so a
loss flown after both filed plans have ended is a flown loss, reported with the pair's one
set of minima (tests/data/eval/after_plan_end.toml, run in fast time, every recommendation
rejected so that nothing changes the flight)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.cli.run import summary_text
from gcs_utm.eval.summary import outcome
from gcs_utm.settings import Settings

DATA = Path(__file__).resolve().parents[1] / "data" / "eval"

pytestmark = [pytest.mark.network, pytest.mark.timeout(120)]


def test_a_loss_after_both_plans_ended_is_flown(tmp_path: Path) -> None:
    options = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_REJECT,
        out_dir=tmp_path,
        figures=False,
    )
    report = run_scenario_blocking(DATA / "after_plan_end.toml", Settings(), options)
    assert report.truth is not None
    (pair,) = report.truth.pairs
    assert pair.pair == ("FW", "MR")
    assert pair.loss_of_separation, pair
    assert pair.first_loss_at_s is not None and pair.first_loss_at_s > 60.0, pair
    # the effective minima of a 25 m and a 15 m volume: 50 m horizontally, 40 m vertically
    assert (pair.minimum_horizontal_m, pair.minimum_vertical_m) == (50.0, 40.0)
    assert pair.horizontal_at_closest_m is not None and pair.horizontal_at_closest_m < 50.0
    o = outcome(report)
    assert o.flown_loss_pairs == (("FW", "MR"),)
    (loss,) = o.flown_losses
    assert loss.cause in ("predicted", "missed") and loss.duration_s > 0.0
    text = summary_text(report, tmp_path / "r.json")
    flown = [line for line in text.splitlines() if line.startswith("  flown FW-MR")]
    assert flown == [
        f"  flown FW-MR (minima 50 m horizontal / 40 m vertical): closest at "
        f"{pair.horizontal_at_closest_m} m horizontal, {pair.vertical_at_closest_m} m "
        "vertical: LOSS OF SEPARATION"
    ]
    assert "minimum 15.0" not in text  # no second set of minima (the configured ones)
