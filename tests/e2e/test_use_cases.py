"""The paper's two use cases end to end: built-in PX4-like vehicles over real UDP on loopback,
all UTM services, an automatic operator, at a speed-up. Assertions are on the run report:
the chain of threats, decisions and uploads, and the separation / geofence outcome measured
on the vehicles' true positions."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario
from gcs_utm.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"
SPEED = 10.0

pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(240)]


async def _run(path: Path, out: Path, **kw: Any) -> dict[str, Any]:
    options = RunOptions(
        speed=SPEED,
        headless=True,
        operator=kw.pop("operator", OperatorMode.AUTO_ACCEPT),
        out_dir=out,
        figures=kw.pop("figures", False),
        **kw,
    )
    return await run_scenario(path, Settings(), options)


def _recs(report: dict[str, Any], kind: str) -> list[dict[str, Any]]:
    return [r for r in report["recommendations"] if r["threat_kind"] == kind]


async def test_use_case_1_late_start_loss_of_separation_resolved(tmp_path: Path) -> None:
    report = await _run(SCENARIOS / "use_case_1.toml", tmp_path, figures=True)
    los = [t for t in report["threats"] if t["kind"] == "LOSS_OF_SEPARATION"]
    assert los, report["threats"]
    first = los[0]
    assert first["uas"] == ["UAS1", "UAS2"]
    # detected well ahead of the predicted loss (the paper: late in UAS1's operation)
    assert first["predicted_event_at_s"] - first["detected_at_s"] >= 30.0
    recs = _recs(report, "LOSS_OF_SEPARATION")
    assert recs, report["recommendations"]
    rec = recs[0]
    assert rec["uas"] == "UAS1"  # the low-priority UAS moves, the high-priority one does not
    assert rec["maneuver"] in {"go_up", "go_down", "go_left", "go_right", "delay", "speed_change"}
    assert len(rec["alternatives"]) >= 2
    assert (rec["decision"], rec["uploaded"], rec["verified"]) == ("accepted", True, True)
    uas1 = next(op for op in report["operations"] if op["id"] == "UAS1")
    assert [p["version"] for p in uas1["plans"]][-1] >= 2
    # flown: the true positions of the simulated vehicles never lose separation
    truth = report["truth"]["pairs"]
    assert truth and not truth[0]["loss_of_separation"], truth
    assert not report["geofence_intrusions"]
    tele = report["telemetry"]
    assert tele and all(v["rate_hz"] > 1.0 for v in tele.values())
    assert (tmp_path / "use_case_1_top.png").stat().st_size > 0


async def test_use_case_2_jamming_suspends_and_neighbour_reroutes(tmp_path: Path) -> None:
    report = await _run(SCENARIOS / "use_case_2.toml", tmp_path)
    kinds = [(t["kind"], t["uas"]) for t in report["threats"]]
    assert ("JAMMING_ATTACK", ["UAS1"]) in kinds
    jam = next(t for t in report["threats"] if t["kind"] == "JAMMING_ATTACK")
    assert 12.0 <= jam["detected_at_s"] <= 20.0
    jam_recs = _recs(report, "JAMMING_ATTACK")
    suspend = [r for r in jam_recs if r["uas"] == "UAS1"]
    assert suspend and suspend[0]["maneuver"] in {"hold", "land"}
    assert suspend[0]["verified"]
    assert any(g["reason"].startswith("JAMMING_ATTACK") for g in report["geofences"])
    reroute = [r for r in report["recommendations"] if r["uas"] == "UAS2"]
    assert reroute, report["recommendations"]
    assert (reroute[0]["decision"], reroute[0]["uploaded"], reroute[0]["verified"]) == (
        "accepted",
        True,
        True,
    )
    # UAS2 never enters the geofence (actual track, not prediction)
    assert not [g for g in report["geofence_intrusions"] if g["uas"] == "UAS2"]


async def test_rejected_recommendation_leads_to_a_different_accepted_one(tmp_path: Path) -> None:
    report = await _run(SCENARIOS / "use_case_1.toml", tmp_path, reject_first=1)
    recs = _recs(report, "LOSS_OF_SEPARATION")
    decisions = [(r["id"], r["version"], r["maneuver"], r["decision"]) for r in recs]
    # The rejected version is either its own entry (another UAS was moved instead) or, when
    # the same UAS got a new version, in the history of the entry that replaced it.
    rejected = [r for r in recs if r["decision"] == "rejected"] + [
        r for r in recs if any(text.startswith("rejected") for _, text in r["history"])
    ]
    assert rejected, (decisions, [r["history"] for r in recs])
    accepted = [r for r in recs if r["decision"] == "accepted"]
    assert accepted, decisions
    # a different recommendation, or a newer version of the rejected one
    assert any(a["id"] != r["id"] or a["version"] > 1 for a in accepted for r in rejected)
    assert accepted[0]["verified"]


async def test_vehicle_that_never_answers_ends_with_failed_upload(tmp_path: Path) -> None:
    text = (SCENARIOS / "use_case_2.toml").read_text()
    text += '\n[[events]]\nat_s = 11.0\nkind = "link_loss"\nuas = "UAS2"\n'
    path = tmp_path / "use_case_2_link_loss.toml"
    path.write_text(text)
    report = await _run(path, tmp_path, duration_s=90.0)
    uas2 = [r for r in report["recommendations"] if r["uas"] == "UAS2" and r["uploaded"] is False]
    failed = [r for r in report["recommendations"] if r["state"] == "failed"]
    assert failed, report["recommendations"]
    assert all(not r["verified"] for r in failed)
    assert failed[0]["error"]
    assert uas2
