"""Late detection and vehicles off their plans, flown end to end in fast time (built-in
vehicles, every recommendation accepted after the automatic operator's delay): no loss of
separation inside the pair's effective minima on the vehicles' true positions, over the
whole flight, and every escalation carries a proposed command (docs/emergency.md, "Immediate
commands"). Scenarios: tests/data/scenarios/late_appearance.toml (a UAS appears about 8 s
before the loss, less than a new plan needs to start) and lagging_vehicle.toml (a UAS 20 s
behind its plan: the tracks predict a loss the filed plans do not show)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.app.report import build_report
from gcs_utm.core.monitoring.loss import separation_ratio
from gcs_utm.scenario import load_scenario
from gcs_utm.settings import Settings

DATA = Path(__file__).resolve().parents[1] / "data" / "scenarios"
pytestmark = [pytest.mark.network, pytest.mark.timeout(120)]


def _fly(name: str, out: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[dict[str, Any], float]:
    """The run's report and the smallest separation ratio flown (true positions, every pair,
    from the first to the last record of both vehicles: not only while plans are in
    progress)."""
    path = DATA / f"{name}.toml"
    seen: dict[str, Any] = {}

    def spy(*args: Any, **kw: Any) -> Any:
        seen["vehicles"] = kw["vehicles"]  # the simulated vehicles: their true positions
        return build_report(*args, **kw)

    monkeypatch.setattr("gcs_utm.app.runner.build_report", spy)
    options = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=out,
        figures=False,
    )
    settings = Settings()
    report = run_scenario_blocking(path, settings, options).to_json()
    return report, _flown_ratio(path, seen["vehicles"], settings)


def _flown_ratio(path: Path, vehicles: Any, settings: Settings) -> float:
    scenario = load_scenario(path)
    frame = scenario.frame
    ops = {int(op.sys_id): op for op in scenario.operations if op.sys_id is not None}
    tracks = {}
    for v in vehicles:
        h = np.asarray(v.position_history, dtype=np.float64)
        e, n = frame.to_local(h[:, 1], h[:, 2])
        tracks[int(v.sys_id)] = (h[:, 0], np.asarray(e), np.asarray(n), h[:, 3])
    worst = math.inf
    ids = sorted(tracks)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            ta, tb = tracks[a][0], tracks[b][0]
            t = np.arange(max(ta[0], tb[0]), min(ta[-1], tb[-1]), 0.1)
            if t.size == 0:
                continue
            pa = [np.interp(t, ta, c) for c in tracks[a][1:]]
            pb = [np.interp(t, tb, c) for c in tracks[b][1:]]
            h_min, v_min = settings.monitoring.effective_minima(
                ops[a].operational_volume_m, ops[b].operational_volume_m
            )
            ratio = separation_ratio(
                np.hypot(pa[0] - pb[0], pa[1] - pb[1]),
                pa[2] - pb[2],
                h_min,
                v_min,
                spherical=settings.monitoring.spherical,
            )
            worst = min(worst, float(ratio.min()))
    return worst


def _escalations_carry_commands(report: dict[str, Any]) -> None:
    """Every escalation names the command it proposes, and a command recommendation (hold
    or a climb/descent in place) was proposed with it."""
    commands = [r for r in report["recommendations"] if r["maneuver"] in {"hold", "goto"}]
    proposed_at = [
        float(t) for r in commands for t, text in r["history"] if text.startswith("proposed")
    ]
    for esc in report["escalations"]:
        assert "proposed" in esc["text"], esc
        assert any(t == pytest.approx(esc["at_s"]) for t in proposed_at), (esc, commands)


def test_a_uas_appearing_seconds_before_the_loss_gets_an_immediate_command(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    report, flown = _fly("late_appearance", tmp_path, monkeypatch)
    los = [t for t in report["threats"] if t["kind"] == "LOSS_OF_SEPARATION"]
    assert los, report["threats"]
    warning_s = los[0]["predicted_event_at_s"] - los[0]["detected_at_s"]
    assert 3.0 <= warning_s <= 10.0  # detected late: less than a new plan needs
    assert flown >= 1.0, f"flown inside the minima (separation ratio {flown:.3f})"
    assert report["escalations"], "the late case must reach the operator"
    _escalations_carry_commands(report)
    commanded = [
        r
        for r in report["recommendations"]
        if r["threat_kind"] == "LOSS_OF_SEPARATION" and r["maneuver"] in {"hold", "goto"}
    ]
    assert commanded and commanded[0]["verified"], report["recommendations"]


def test_a_uas_behind_its_plan_does_not_fly_into_the_loss_its_track_predicts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    report, flown = _fly("lagging_vehicle", tmp_path, monkeypatch)
    los = [t for t in report["threats"] if t["kind"] == "LOSS_OF_SEPARATION"]
    assert los, report["threats"]
    _escalations_carry_commands(report)
    assert flown >= 1.0, f"flown inside the minima (separation ratio {flown:.3f})"
