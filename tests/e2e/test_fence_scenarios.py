"""Geofences in closed loop (``gcs-utm run --speed max``, built-in vehicles): a fence that
appears around a hovering multirotor gets it out (tests/e2e/scenarios)."""

from __future__ import annotations

import math
from pathlib import Path

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings

DATA = Path(__file__).resolve().parent / "scenarios"
SAMPLE_S = 0.5  # the report's track samples


def test_a_fence_appearing_around_a_hovering_uas_gets_it_out(tmp_path: Path) -> None:
    # The alert area appears at 55 s around the UAS hovering at its destination (80 m
    # fence, 10 m volume). Before, TD tried only escape, which has nowhere to rejoin: every
    # decision escalated "no feasible alternative" and the UAS hovered inside to the end
    # (45 s). Now it is offered a way out and leaves.
    options = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        figures=False,
    )
    report = run_scenario_blocking(DATA / "fence_hover_inside.toml", Settings(), options)
    assert not [e for e in report.escalations if "no feasible alternative" in e.text]
    out = [r for r in report.recommendations if r.maneuver in ("hold", "return_home")]
    assert out and out[0].verified, [r.maneuver for r in report.recommendations]
    (intrusion,) = report.geofence_intrusions
    assert intrusion.first_at_s == 55.0
    assert intrusion.samples_inside * SAMPLE_S <= 25.0, intrusion
