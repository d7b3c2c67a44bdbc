"""What keeps ``gcs-utm scenario check`` fast on a dense airspace: lookups of an operation or
its vehicle by id (once per operation in the report), the JSON report written line by line,
and the dense airspace of ``gcs-utm bench strategic`` checked end to end."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from gcs_utm.bench.dense_airspace import write_dense_scenario
from gcs_utm.cli.scenario import report_document, write_json
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import strategic_check
from gcs_utm.scenario import load_any


def test_lookups_by_id_find_the_first_and_name_a_missing_id(tmp_path: Path) -> None:
    sc = load_any(write_dense_scenario(tmp_path / "dense.toml", 50, 3))
    for op in sc.operations:
        assert sc.operation(op.id) is op
        assert sc.vehicle(op.id).operation_id == op.id
    with pytest.raises(KeyError, match="D50"):
        sc.vehicle("D50")
    with pytest.raises(KeyError, match="nope"):
        sc.operation("nope")
    first = sc.operations[0]
    twice = replace(sc, operations=(first, *sc.operations))  # a fresh index
    assert twice.operation(first.id) is first


def test_json_report_is_the_document_one_element_per_line(tmp_path: Path) -> None:
    sc = load_any(write_dense_scenario(tmp_path / "dense.toml", 300, 5))
    report = strategic_check(sc.operations, sc.geofences, sc.frame, MonitoringConfig())
    assert len(report.conflicts) >= 3
    doc = report_document(sc, report)
    out = io.StringIO()
    write_json(doc, out)
    text = out.getvalue()
    assert json.loads(text) == doc
    assert (
        len(text.splitlines())
        == sum(len(v) + 2 if isinstance(v, list) and v else 1 for v in doc.values()) + 2
    )


def test_dense_airspace_checked_end_to_end(tmp_path: Path) -> None:
    path = write_dense_scenario(tmp_path / "dense.toml", 400, 7)
    done = subprocess.run(
        [sys.executable, "-m", "gcs_utm", "scenario", "check", str(path), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    doc = json.loads(done.stdout)
    sc = load_any(path)
    report = strategic_check(sc.operations, sc.geofences, sc.frame, MonitoringConfig())
    assert doc == json.loads(json.dumps(report_document(sc, report)))
    assert len(doc["operations"]) == 400
    assert len(doc["conflicts"]) == len(report.conflicts) > 0


def test_bench_dense_profile_reports_the_command_and_its_stages() -> None:
    import argparse

    from gcs_utm.bench import strategic

    parser = argparse.ArgumentParser()
    strategic.add_arguments(parser)
    args = parser.parse_args(["--profile", "dense", "--dense-plans", "150", "--cli-runs", "1"])
    args.runs = 1
    records = {r["benchmark"]: r for r in strategic.run(args)}
    cli, stages = records["strategic.scenario_check"], records["strategic.dense_stages"]
    assert cli["n"] == stages["n"] == 150
    assert cli["conflicts"] == stages["conflicts"]
    assert float(cli["cpu_median_ms"]) > 0  # type: ignore[arg-type]
    assert {"load_ms", "check_ms"} <= set(stages)
