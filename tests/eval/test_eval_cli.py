"""``gcs-utm eval``: runs scenarios in fast time with an automatic operator and writes each
report plus summary.json and summary.md; bad input is one clear error."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from gcs_utm.cli import main

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.network, pytest.mark.timeout(180)]


def test_eval_runs_files_and_generated_encounters(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = ROOT / "config" / "scenarios" / "use_case_1.toml"
    code = main(["eval", str(scenario), "--generate", "1", "--seed", "11", "--out", str(tmp_path)])
    assert code == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["scenarios"] == 2 and summary["failed_runs"] == 0
    names = [o["scenario"] for o in summary["outcomes"]]
    assert names[0] == "use_case_1" and names[1].startswith("enc_11_0000_")
    for name in names:
        assert (tmp_path / "reports" / f"{name}.json").is_file()
        assert not (tmp_path / "reports" / f"{name}.sqlite").exists()
    uc1 = summary["outcomes"][0]
    assert uc1["predicted_pairs"] == [["UAS1", "UAS2"]] and uc1["avoided"] == 1
    assert uc1["accepted_plans"] and uc1["detection_to_verified_upload_s"]
    md = (tmp_path / "summary.md").read_text()
    assert "| predicted losses avoided |" in md and "| use_case_1 |" in md
    assert "| predicted losses avoided |" in capsys.readouterr().out


def test_eval_auto_reject_applies_nothing(tmp_path: Path) -> None:
    scenario = ROOT / "config" / "scenarios" / "use_case_1.toml"
    assert main(["eval", str(scenario), "--auto-reject", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["accepted_plans"] == 0
    assert summary["predicted_losses"] == 1


def test_eval_bad_input_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["eval", str(tmp_path / "nope.toml"), "--out", str(tmp_path)]) == 2
    assert "no such scenario file" in capsys.readouterr().err
    assert main(["eval", "--out", str(tmp_path)]) == 2
    assert "give scenario files or --generate N" in capsys.readouterr().err


def test_eval_generates_a_profile_and_reports_throughput(tmp_path: Path) -> None:
    args = ["eval", "--generate", "1", "--seed", "3", "--profile", "vertical"]
    assert main([*args, "--jobs", "1", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [p["profile"] for p in summary["profiles"]] == ["vertical"]
    assert summary["outcomes"][0]["scenario"].startswith("enc_3_0000_vertical_")
    assert summary["jobs"] == 1 and summary["encounters_per_minute"] > 0.0
    assert "| elapsed (jobs), encounters per minute |" in (tmp_path / "summary.md").read_text()


def test_eval_runs_one_process_per_cpu_by_default(tmp_path: Path) -> None:
    from gcs_utm.eval.run import EvalOptions

    assert EvalOptions(out_dir=tmp_path).jobs == (os.cpu_count() or 1)
