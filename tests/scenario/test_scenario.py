# ruff: noqa: E501  (TOML fixtures and their one-line replacements read best unwrapped)
"""Scenario loaders: our TOML format (good files and every class of bad input), the paper's
GAUSS files, the use-case geometry, and the ``scenario check`` CLI end to end."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pytest

from gcs_utm.cli import config as config_cli
from gcs_utm.cli import scenario as scenario_cli
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import strategic_check
from gcs_utm.model import GeofenceShape, VehicleKind
from gcs_utm.scenario import EventKind, ScenarioError, load_any, load_gauss, load_scenario

REPO = Path(__file__).resolve().parents[2]
SCEN = REPO / "config/scenarios"
GAUSS = REPO / "tests" / "data" / "gauss"

BASE = """
[scenario]
name = "t"
duration_s = 100.0

[airspace]
origin_lat_deg = 40.0
origin_lon_deg = -3.0
ground_elevation_amsl_m = 600.0

[[operations]]
id = "A"
sys_id = 1
priority = 1
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
waypoints = [
    { east_m = 0.0, north_m = 0.0, alt_agl_m = 30.0 },
    { east_m = 100.0, north_m = 0.0, alt_agl_m = 30.0 },
    { lat_deg = 40.001, lon_deg = -3.0, alt_amsl_m = 650.0, speed_mps = 10.0 },
]

[[operations]]
id = "B"
sys_id = 2
priority = 2
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
waypoints = [
    { east_m = 0.0, north_m = 500.0, alt_agl_m = 30.0, t_s = 10.0 },
    { east_m = 0.0, north_m = 600.0, alt_agl_m = 30.0, t_s = 40.0 },
]

[[geofences]]
id = "G1"
polygon = [{ east_m = 0.0, north_m = 0.0 }, { east_m = 50.0, north_m = 0.0 }, { east_m = 0.0, north_m = 50.0 }]
min_alt_agl_m = 0.0
max_alt_agl_m = 120.0
start_s = 0.0
end_s = 50.0

[[events]]
at_s = 20.0
kind = "alert_area"
reason = "wildfire"
duration_s = 30.0
area = { cylinder = { east_m = 300.0, north_m = 300.0, radius_m = 40.0 }, min_alt_agl_m = 0.0, max_alt_agl_m = 200.0 }
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


def test_good_file_loads_with_conversions_and_times(tmp_path: Path) -> None:
    sc = load_scenario(_write(tmp_path, BASE), t0_s=1000.0)
    a = sc.operation("A")
    w = a.plan.waypoints
    assert w[0].t_s == 1000.0
    assert w[0].alt_amsl_m == 630.0  # 30 m AGL + 600 m ground
    assert w[1].t_s == pytest.approx(1020.0, abs=1e-3)  # 100 m at 5 m/s
    enu = [sc.frame.wgs84_to_enu(p.lat_deg, p.lon_deg, p.alt_amsl_m) for p in (w[1], w[2])]
    seg = math.dist([float(v) for v in enu[0]], [float(v) for v in enu[1]])
    assert w[2].t_s - w[1].t_s == pytest.approx(seg / 10.0, rel=1e-6)
    e, n = sc.frame.wgs84_to_enu(w[1].lat_deg, w[1].lon_deg, 600.0)[:2]
    assert (float(e), float(n)) == pytest.approx((100.0, 0.0), abs=1e-3)
    assert sc.operation("B").plan.start_t_s == 1010.0
    (g,) = sc.geofences
    assert g.shape is GeofenceShape.POLYGON and g.start_t_s == 1000.0 and g.end_t_s == 1050.0
    (ev,) = sc.events
    assert ev.kind is EventKind.ALERT_AREA and ev.t_s == 1020.0
    assert ev.area is not None and ev.area.start_t_s == 1020.0 and ev.area.end_t_s == 1050.0
    assert ev.area.reason == "wildfire"
    assert [v.operation_id for v in sc.vehicles] == ["A", "B"]
    assert sc.vehicle("A").home.alt_amsl_m == 600.0


@pytest.mark.parametrize(
    ("old", "new", "item", "field", "fragment"),
    [
        ('name = "t"', 'name = "t"\ncolour = 3', "scenario", "colour", "unknown key"),
        ("priority = 2", "priority = 2\nspeed = 1", "operations[1] (B)", "speed", "unknown key"),
        (
            "{ east_m = 0.0, north_m = 50.0 }]",
            "]",
            "geofences[0] (G1)",
            "polygon",
            "at least 3 vertices",
        ),
        (
            "{ east_m = 50.0, north_m = 0.0 }, { east_m = 0.0, north_m = 50.0 }]",
            "{ east_m = 50.0, north_m = 50.0 }, { east_m = 50.0, north_m = 0.0 }, { east_m = 0.0, north_m = 50.0 }]",
            "geofences[0] (G1)",
            "polygon",
            "intersects itself",
        ),
        (
            "min_alt_agl_m = 0.0\nmax_alt_agl_m = 120.0",
            "min_alt_agl_m = 130.0\nmax_alt_agl_m = 120.0",
            "geofences[0] (G1)",
            "min_alt",
            "above",
        ),
        ("end_s = 50.0", "end_s = -5.0", "geofences[0] (G1)", "start_s", "after end_s"),
        (
            "cruise_speed_mps = 5.0\nflight_geometry_m = 5.0\noperational_volume_m = 10.0\nwaypoints = [\n    { east_m = 0.0, north_m = 500.0",
            "cruise_speed_mps = nan\nflight_geometry_m = 5.0\noperational_volume_m = 10.0\nwaypoints = [\n    { east_m = 0.0, north_m = 500.0",
            "operations[1] (B)",
            "cruise_speed_mps",
            "finite",
        ),
        (
            "alt_amsl_m = 650.0",
            "alt_amsl_m = inf",
            "operations[0] (A)",
            "waypoints[2].alt_amsl_m",
            "finite",
        ),
        (
            "lat_deg = 40.001",
            "lat_deg = 91.0",
            "operations[0] (A)",
            "waypoints[2].lat_deg",
            "[-90, 90]",
        ),
        (
            "origin_lat_deg = 40.0",
            "origin_lat_deg = -95.0",
            "airspace",
            "origin_lat_deg",
            "[-90, 90]",
        ),
        ("t_s = 40.0", "t_s = 5.0", "operations[1] (B)", "waypoints[1].t_s", "backwards"),
        ('id = "B"', 'id = "A"', "operations[1] (A)", "id", "duplicate"),
        ("sys_id = 2", "sys_id = 1", "operations[1] (B)", "sys_id", "also used by A"),
        (
            'reason = "wildfire"',
            'reason = "wildfire"\nuas = "C"',
            "events[0] (alert_area)",
            "uas",
            "unknown uas 'C'",
        ),
        ('kind = "alert_area"', 'kind = "meteor"', "events[0] (meteor)", "kind", "expected one of"),
        (
            "alt_agl_m = 30.0, t_s = 10.0",
            "t_s = 10.0",
            "operations[1] (B)",
            "waypoints[0].alt_agl_m",
            "missing",
        ),
    ],
)
def test_bad_input_names_file_item_and_field(
    tmp_path: Path, old: str, new: str, item: str, field: str, fragment: str
) -> None:
    assert old in BASE, old
    path = _write(tmp_path, BASE.replace(old, new, 1))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert (err.file, err.item, err.field) == (str(path), item, field), str(err)
    assert fragment in err.message, str(err)


def test_malformed_toml_names_the_line(tmp_path: Path) -> None:
    path = _write(tmp_path, BASE.replace("priority = 2", "priority = = 2"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.file == str(path)
    assert info.value.field == f"line {BASE.splitlines().index('priority = 2') + 1}"


def test_use_case_1_conflict_free_as_filed_and_in_conflict_with_the_delay() -> None:
    sc = load_scenario(SCEN / "use_case_1.toml")
    uas1, uas2 = sc.operations
    assert (uas1.vehicle_kind, uas2.vehicle_kind) == (
        VehicleKind.MULTIROTOR,
        VehicleKind.FIXED_WING,
    )
    assert uas2.priority > uas1.priority
    assert sc.vehicle("UAS1").start_delay_s == 3.0
    assert max(op.plan.end_t_s for op in sc.operations) <= 240.0
    cfg = MonitoringConfig()
    assert strategic_check(sc.operations, sc.geofences, sc.frame, cfg).conflicts == ()
    flown = strategic_check(scenario_cli.delayed_operations(sc), sc.geofences, sc.frame, cfg)
    (c,) = flown.conflicts
    assert {c.a, c.b} == {"UAS1", "UAS2"}
    assert c.min_horizontal_m < cfg.separation_horizontal_m
    assert c.first_loss_t_s > 0.8 * uas1.plan.end_t_s  # late in UAS1's operation


def test_use_case_2_jamming_then_geofence_conflict_with_margin() -> None:
    from gcs_utm.model import Geofence, GeofenceId, LatLon

    sc = load_scenario(SCEN / "use_case_2.toml")
    (jam,) = sc.events
    assert jam.kind is EventKind.GNSS_JAMMING and jam.uas == "UAS1" and jam.at_s == 12.0
    assert {op.priority for op in sc.operations} == {10}
    assert strategic_check(sc.operations, (), sc.frame, MonitoringConfig()).conflicts == ()
    w = sc.operation("UAS1").plan.waypoints[0]
    fence = Geofence(
        id=GeofenceId("jam"),
        shape=GeofenceShape.CYLINDER,
        center=LatLon(lat_deg=w.lat_deg, lon_deg=w.lon_deg),
        radius_m=50.0,
        min_alt_amsl_m=600.0,
        max_alt_amsl_m=900.0,
        start_t_s=jam.t_s,
    )
    rep = strategic_check(sc.operations[1:], [fence], sc.frame, MonitoringConfig())
    (x,) = rep.crossings
    assert x.operation_id == "UAS2" and x.entry_t_s - jam.t_s >= 40.0


def _gauss_pairs() -> list[tuple[Path, Path | None]]:
    out: list[tuple[Path, Path | None]] = []
    for folder in ("paper_dev", "paper_master"):
        for j in sorted((GAUSS / folder).glob("*.json")):
            if j.with_suffix(".yaml").exists():
                out.append((j, None))
            elif "4c89f8f" in j.stem:
                out.append((j, j.with_name("madrid_loss_separation.yaml")))
            else:  # geofence files: paired with the scenario YAML that names its operations
                out.append((j, j.with_name("madrid.yaml")))
    return out


@pytest.mark.data
def test_every_gauss_file_loads() -> None:
    pairs = _gauss_pairs()
    assert len(pairs) >= 12
    for json_path, yaml_path in pairs:
        sc = load_gauss(json_path, yaml_path)
        assert sc.operations, json_path
        for op in sc.operations:
            assert op.icao24 is not None and len(op.icao24) == 6
            assert abs(op.plan.waypoints[0].lat_deg - 40.66) < 0.2, json_path
    sc = load_gauss(GAUSS / "paper_dev/madrid_start_geofence.json", GAUSS / "paper_dev/madrid.yaml")
    (g,) = sc.geofences
    assert g.radius_m == 60.0 and g.shape is GeofenceShape.CYLINDER
    uc2 = load_gauss(GAUSS / "paper_master/use_case_geo_conflict.json")
    (ev,) = uc2.events
    assert ev.kind is EventKind.GNSS_JAMMING and ev.uas == "3434007" and ev.at_s == 20.0
    # started at 8 s (auto_start), on its plan's timing: its mission begins where the plan
    # is at 8 s (the wind-turbine climb at 1 m/s: 8 m above its first waypoint)
    v = uc2.vehicle("3434007")
    first = uc2.operation("3434007").plan.waypoints[0]
    assert v.start_delay_s == 0.0 and v.plan.waypoints[0].t_s == 8.0
    assert v.plan.waypoints[0].alt_amsl_m - first.alt_amsl_m == pytest.approx(8.0, abs=0.01)
    assert v.plan.waypoints[1:] == uc2.operation("3434007").plan.waypoints[1:]
    # GAUSS z is up from the origin's ellipsoidal height (675 m in madrid_loss_separation)
    ls = load_gauss(GAUSS / "paper_dev/madrid_loss_separation.json")
    assert ls.operation("3434000").plan.waypoints[0].alt_amsl_m == pytest.approx(675 + 70, abs=0.1)
    assert ls.operation("3434009").vehicle_kind is VehicleKind.FIXED_WING


@pytest.mark.data
def test_gauss_start_times_and_safety_distance(capsys: pytest.CaptureFixture[str]) -> None:
    """auto_start gives when GAUSS's simulator starts a vehicle, which then flies on its plan's
    timing (never late): madrid_loss_separation starts 3434000 at 5 s, its first stamp, and
    3434009 at 2 s, 2 s into its plan. Its safetyDistance (350 m) is a 3D minimum: the fixed
    wing at 400 m passes 330 m over the multirotor at 70 m at t ~ 335 s, a conflict in the
    filed plans, which the start times do not change."""
    dev = load_gauss(GAUSS / "paper_dev/madrid_loss_separation.json")
    assert [v.start_delay_s for v in dev.vehicles] == [0.0, 0.0]
    assert dev.vehicle("3434000").plan == dev.operation("3434000").plan
    assert dev.vehicle("3434009").plan.start_t_s == 2.0
    assert dev.safety_distance_m == 350.0
    master = load_gauss(GAUSS / "paper_master/madrid_loss_separation.json")
    assert master.operation("3434000").plan.start_t_s == 20.0  # first stamp 20 s, auto_start 20 s
    assert master.vehicle("3434000").plan == master.operation("3434000").plan
    path = str(GAUSS / "paper_dev/madrid_loss_separation.json")
    for argv in ([], ["--apply-delays"]):
        code, out, _ = _cli(["scenario", "check", path, "--json", *argv], capsys)
        doc = json.loads(out)
        assert code == 0
        assert doc["separation"] == {
            "mode": "sphere",
            "safety_distance_m": 350.0,
            "horizontal_m": None,
            "vertical_m": None,
        }
        (c,) = doc["conflicts"]
        assert (c["a"], c["b"]) == ("3434000", "3434009")
        assert c["first_loss_s"] == pytest.approx(331.1, abs=0.6)
        assert c["min_distance_m"] == pytest.approx(330.0, abs=1.0)
        assert c["min_vertical_m"] == pytest.approx(330.0, abs=1.0)
    # use_case_loss_separation: 15 m safety distance, 10.5 m at t ~ 76 s
    code, out, _ = _cli(
        ["scenario", "check", str(GAUSS / "paper_dev/use_case_loss_separation.json"), "--json"],
        capsys,
    )
    (c,) = json.loads(out)["conflicts"]
    assert c["first_loss_s"] == pytest.approx(75.7, abs=0.6) and c["min_distance_m"] < 15.0
    # a scenario without its own rule keeps the settings' cylinder minima
    assert load_any(str(SCEN / "use_case_1.toml")).safety_distance_m is None


def test_gauss_without_yaml_is_one_clear_error() -> None:
    with pytest.raises(ScenarioError, match="no YAML with the origin"):
        load_gauss(GAUSS / "paper_dev/no_geofences.json")


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    scenario_cli.register(sub)
    config_cli.register(sub)
    args = parser.parse_args(argv)
    code = args.func(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_check_filed_and_flown(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _cli(["scenario", "check", str(SCEN / "use_case_1.toml")], capsys)
    assert code == 0 and "no conflicts" in out
    code, out, _ = _cli(
        ["scenario", "check", str(SCEN / "use_case_1.toml"), "--apply-delays", "--json"], capsys
    )
    doc = json.loads(out)
    assert code == 0
    assert [o["id"] for o in doc["operations"]] == ["UAS1", "UAS2"]
    (c,) = doc["conflicts"]
    assert (c["a"], c["b"]) == ("UAS1", "UAS2")
    assert 150.0 < c["first_loss_s"] < 175.0 and 40.0 < c["min_distance_m"] < 50.0


def test_cli_reports_a_crafted_conflict_and_a_crossing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # B flies straight through A's first leg at the same time and height, and A's plan crosses G1
    text = BASE.replace(
        "north_m = 500.0, alt_agl_m = 30.0, t_s = 10.0",
        "north_m = -50.0, alt_agl_m = 30.0, t_s = 0.0",
    )
    text = text.replace(
        "north_m = 600.0, alt_agl_m = 30.0, t_s = 40.0",
        "north_m = 50.0, alt_agl_m = 30.0, t_s = 20.0",
    )
    text = text.replace(
        "{ east_m = 0.0, north_m = -50.0", "{ east_m = 50.0, north_m = -50.0"
    ).replace(
        "{ east_m = 0.0, north_m = 50.0, alt_agl_m = 30.0, t_s = 20.0",
        "{ east_m = 50.0, north_m = 50.0, alt_agl_m = 30.0, t_s = 20.0",
    )
    code, out, _ = _cli(["scenario", "check", str(_write(tmp_path, text))], capsys)
    assert code == 0
    assert "CONFLICT as filed: A x B" in out
    assert "GEOFENCE as filed: A enters G1 at t=0.0 s" in out


def test_cli_invalid_file_exit_2_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, BASE.replace("sys_id = 2", "sys_id = 1"))
    code, out, err = _cli(["scenario", "check", str(path)], capsys)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "operations[1] (B): sys_id:" in err


def test_cli_config_default_then_check_round_trip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, text, _ = _cli(["config", "default"], capsys)
    assert code == 0 and "[store]" in text
    path = tmp_path / "default.toml"
    path.write_text(text)
    code, out, _ = _cli(["config", "check", str(path)], capsys)
    assert code == 0 and "ok" in out
    path.write_text("[store]\nqueue_sise = 3\n")
    code, _, err = _cli(["config", "check", str(path)], capsys)
    assert code == 2 and "store.queue_sise: unknown key" in err and "queue_size" in err
