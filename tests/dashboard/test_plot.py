"""Plots and exports draw the report's data: counts of plans, alternatives, tracks, geofences."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from gcs_utm.cli import main
from gcs_utm.dashboard.plot import ReportError, export_all, load_report, to_geojson, to_kml


def _report() -> dict[str, Any]:
    wp = [[40.0, -3.0, 700.0, 0.0], [40.001, -3.001, 710.0, 30.0], [40.002, -3.0, 700.0, 60.0]]
    alt = [[40.0, -3.0, 700.0, 0.0], [40.001, -3.0015, 690.0, 35.0], [40.002, -3.0, 700.0, 66.0]]
    return {
        "scenario": "t",
        "origin": {"lat_deg": 40.0, "lon_deg": -3.0},
        "operations": [
            {
                "id": "UAS1",
                "operational_volume_m": 20.0,
                "plans": [{"version": 1, "waypoints": wp}, {"version": 2, "waypoints": alt}],
            },
            {
                "id": "UAS2",
                "operational_volume_m": 20.0,
                "plans": [{"version": 1, "waypoints": wp[::-1]}],
            },
        ],
        "tracks": {"UAS1": [[0.0, 40.0, -3.0, 700.0], [1.0, 40.0001, -3.0001, 701.0]]},
        "geofences": [
            {
                "id": "g1",
                "shape": "cylinder",
                "center": {"lat_deg": 40.001, "lon_deg": -3.0},
                "radius_m": 40.0,
                "min_alt_amsl_m": 0.0,
                "max_alt_amsl_m": 900.0,
            },
            {
                "id": "g2",
                "shape": "polygon",
                "min_alt_amsl_m": 0.0,
                "max_alt_amsl_m": 900.0,
                "vertices": [
                    {"lat_deg": 40.0, "lon_deg": -3.002},
                    {"lat_deg": 40.0005, "lon_deg": -3.002},
                    {"lat_deg": 40.0005, "lon_deg": -3.0025},
                ],
            },
        ],
        "threats": [
            {
                "kind": "LOSS_OF_SEPARATION",
                "position": {"lat_deg": 40.001, "lon_deg": -3.001, "alt_amsl_m": 705.0},
            }
        ],
        "recommendations": [
            {
                "uas": "UAS1",
                "alternatives": [
                    {"maneuver": "go_left", "selected": True, "waypoints": alt},
                    {"maneuver": "go_down", "selected": False, "waypoints": wp},
                ],
            }
        ],
    }


def test_export_draws_every_item(tmp_path: Path) -> None:
    summary = export_all(_report(), tmp_path, stem="r")
    assert (
        summary.plans,
        summary.alternatives,
        summary.tracks,
        summary.geofences,
        summary.conflict_points,
    ) == (3, 2, 1, 2, 1)
    for f in summary.files:
        assert f.stat().st_size > 0
    assert (tmp_path / "r_top.png").read_bytes()[:4] == b"\x89PNG"


def test_geojson_and_kml_contents() -> None:
    gj = to_geojson(_report())
    kinds = [f["properties"]["kind"] for f in gj["features"]]
    assert kinds.count("plan") == 3 and kinds.count("geofence") == 2
    assert kinds.count("track") == 1 and kinds.count("alternative") == 2
    ring = next(f for f in gj["features"] if f["properties"].get("id") == "g1")
    assert ring["geometry"]["coordinates"][0][0] == ring["geometry"]["coordinates"][0][-1]
    kml = to_kml(_report())
    assert kml.count("<Placemark>") == len(gj["features"])


def test_cli_plot_and_bad_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "rep.json"
    path.write_text(json.dumps(_report()))
    assert main(["plot", str(path)]) == 0
    assert "3 plans, 2 alternatives" in capsys.readouterr().out
    bad = tmp_path / "bad.json"
    bad.write_text('{"operations": []}')
    assert main(["plot", str(bad)]) == 2
    assert "origin" in capsys.readouterr().err
    with pytest.raises(ReportError):
        load_report(tmp_path / "missing.json")
