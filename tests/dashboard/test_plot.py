"""Plots and exports draw the report's data: counts of plans, alternatives, tracks, geofences."""

from __future__ import annotations

import json
import math
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


# ---- time-series figures on a geometry with known answers -------------------------------------

LAT0, LON0 = 40.0, -3.0
K = math.cos(math.radians(LAT0))


def _ll(east_m: float, north_m: float) -> tuple[float, float]:
    """Inverse of the plot module's equirectangular projection around (LAT0, LON0)."""
    return LAT0 + north_m / 110_540.0, LON0 + east_m / (111_320.0 * K)


def _crossing_report() -> dict[str, Any]:
    """UAS1 flies east along north=0 at 10 m/s, UAS2 north along east=0 at 10 m/s but starts
    2 s late: as filed-and-late they pass 14.14 m apart at t = 11 s. Flown, UAS2 went along
    east=50 on time: 35.36 m at t = 12.5 s. A 20 m geofence at (0, 60) is 30 m from UAS2's
    flown path at its closest (t = 16 s)."""

    def wp(e: float, n: float, t: float) -> list[float]:
        lat, lon = _ll(e, n)
        return [lat, lon, 700.0, t]

    def track(f: Any) -> list[list[float]]:
        out = []
        for k in range(41):
            t = k * 0.5
            e, n = f(t)
            lat, lon = _ll(e, n)
            out.append([t, lat, lon, 700.0])
        return out

    clat, clon = _ll(0.0, 60.0)
    return {
        "scenario": "crossing",
        "origin": {"lat_deg": LAT0, "lon_deg": LON0, "ground_elevation_amsl_m": 650.0},
        "separation_minimum": {"mode": "cylinder", "horizontal_m": 50.0, "vertical_m": 15.0},
        "operations": [
            {
                "id": "UAS1",
                "start_delay_s": 0.0,
                "plans": [{"version": 1, "waypoints": [wp(-100, 0, 0), wp(100, 0, 20)]}],
            },
            {
                "id": "UAS2",
                "start_delay_s": 2.0,
                "plans": [
                    {"version": 1, "waypoints": [wp(0, -100, 0), wp(0, 100, 20)]},
                    {
                        "version": 2,
                        "reason": "LOSS_OF_SEPARATION: go_right",
                        "waypoints": [wp(50, -100, 0), wp(50, 100, 20)],
                    },
                ],
            },
        ],
        "tracks": {
            "UAS1": track(lambda t: (-100 + 10 * t, 0.0)),
            "UAS2": track(lambda t: (50.0, -100 + 10 * t)),
        },
        "geofences": [
            {
                "id": "g1",
                "shape": "cylinder",
                "center": {"lat_deg": clat, "lon_deg": clon},
                "radius_m": 20.0,
                "min_alt_amsl_m": 650.0,
                "max_alt_amsl_m": 800.0,
                "start_s": 0.0,
                "end_s": None,
                "exempt": ["UAS1"],
            }
        ],
        "threats": [{"kind": "LOSS_OF_SEPARATION", "uas": ["UAS1", "UAS2"], "detected_at_s": 3.0}],
        "recommendations": [
            {"uas": "UAS2", "maneuver": "go_right", "decision": "accepted", "created_at_s": 4.0}
        ],
    }


def test_time_series_figures_draw_the_minima_of_the_report(tmp_path: Path) -> None:
    summary = export_all(_crossing_report(), tmp_path, stem="x")
    for name in ("x_top.png", "x_3d.png", "x_altitude.png", "x_separation.png", "x_geofence.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:4] == b"\x89PNG" and len(data) > 10_000, name
    assert summary.altitude_profiles == 2
    # filed plans with UAS2 2 s late: closest at t = 11 s, |(10, -10)| = 14.14 m
    assert summary.min_planned_separation_m["UAS1|UAS2"] == pytest.approx(14.142, abs=0.01)
    # flown: closest at t = 12.5 s, |(-25, 25)| = 35.36 m
    assert summary.min_separation_m["UAS1|UAS2"] == pytest.approx(35.355, abs=0.01)
    # UAS2 passes 50 m from the centre of a 20 m geofence; UAS1 is exempt from it
    assert summary.min_geofence_distance_m == {"UAS2|g1": pytest.approx(30.0, abs=0.01)}


def test_series_follow_the_separation_rule_and_skip_what_is_absent(tmp_path: Path) -> None:
    report = _crossing_report()
    report["separation_minimum"] = {"mode": "sphere", "safety_distance_m": 40.0}
    report["tracks"]["UAS2"] = [[s[0], s[1], s[2], 730.0] for s in report["tracks"]["UAS2"]]
    report["geofences"] = []
    summary = export_all(report, tmp_path, stem="s")
    # sphere mode draws the 3D distance: hypot(35.36, 30)
    assert summary.min_separation_m["UAS1|UAS2"] == pytest.approx(
        math.hypot(35.355, 30.0), abs=0.01
    )
    assert not (tmp_path / "s_geofence.png").exists()
    assert (tmp_path / "s_separation.png").stat().st_size > 0


def _checked_figures(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str, bool, list[Any]]]:
    """For every figure the plot module saves, per axes: (figure title, axes title, has a
    legend, window boxes of its texts), taken as it is saved."""
    from matplotlib.figure import Figure

    seen: list[tuple[str, str, bool, list[Any]]] = []
    original = Figure.savefig

    def keep(self: Any, *args: Any, **kwargs: Any) -> Any:
        out = original(self, *args, **kwargs)
        renderer = self.canvas.get_renderer()
        for ax in self.axes:
            boxes = [t.get_window_extent(renderer) for t in ax.texts if t.get_text()]
            name = f"{id(self)} {self.get_suptitle()}"
            seen.append((name, ax.get_title(), ax.get_legend() is not None, boxes))
        return out

    monkeypatch.setattr(Figure, "savefig", keep)
    return seen


def test_every_plot_has_a_legend_and_no_label_overlaps(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    report = _crossing_report()
    # four detections a second apart and two answers: their labels used to overlap
    report["threats"] += [
        {"kind": k, "uas": ["UAS1", "UAS2"], "detected_at_s": t}
        for k, t in (
            ("GEOFENCE_CONFLICT", 13.0),
            ("UAS_OUT_OV", 14.0),
            ("GEOFENCE_INTRUSION", 15.0),
            ("LACK_OF_BATTERY", 16.0),
        )
    ]
    report["recommendations"].append(
        {"uas": "UAS1", "maneuver": "go_up", "decision": "accepted", "created_at_s": 4.5}
    )
    seen = _checked_figures(monkeypatch)
    export_all(report, tmp_path, stem="o")
    assert len({fig for fig, _, _, _ in seen}) == 5
    for fig, title, has_legend, boxes in seen:
        if not title.startswith("close-up"):  # the top view's zoom shares its legend
            assert has_legend, (fig, title)
        for i, a in enumerate(boxes):
            for b in boxes[i + 1 :]:
                assert not a.overlaps(b), (fig, title, a, b)


def test_separation_names_both_axes_so_a_vertical_pass_is_not_a_loss(tmp_path: Path) -> None:
    report = _crossing_report()
    summary = export_all(report, tmp_path, stem="l")
    assert summary.separation_verdict["UAS1|UAS2"].startswith("LOSS of separation")
    # the same horizontal pass (35 m < 50 m) with UAS2 30 m higher: separated vertically
    report["tracks"]["UAS2"] = [[s[0], s[1], s[2], 730.0] for s in report["tracks"]["UAS2"]]
    summary = export_all(report, tmp_path, stem="v")
    verdict = summary.separation_verdict["UAS1|UAS2"]
    assert verdict == (
        "separated: horizontal below 50 m only while vertical >= 15 m (least 30.0 m)"
    )
