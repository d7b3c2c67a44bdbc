"""Bad input where scenarios and configuration enter (issue 21, items 7-9): one shared polygon
rule, plausibility bounds, recursion-safe loading, ``--json`` errors, folders, GAUSS YAML
entry points and speed factors. Each is one clear error, never a traceback."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from gcs_utm.cli import build_parser, main
from gcs_utm.scenario import ScenarioError, load_any, load_gauss, load_scenario
from gcs_utm.validation import nesting_depth, polygon_problem
from tests.scenario.test_scenario import BASE, GAUSS

BOW_TIE = (
    "polygon = [{ east_m = 0.0, north_m = 0.0 }, { east_m = 50.0, north_m = 50.0 },"
    " { east_m = 50.0, north_m = 0.0 }, { east_m = 0.0, north_m = 50.0 }]"
)
G1_POLYGON = (
    "polygon = [{ east_m = 0.0, north_m = 0.0 }, { east_m = 50.0, north_m = 0.0 },"
    " { east_m = 0.0, north_m = 50.0 }]"
)
DEEP = "a = " + "[" * 5000 + "]" * 5000 + "\n"
DEEP_TABLES = "a = " + "{ b = " * 5000 + "1" + " }" * 5000 + "\n"


def _write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _error(path: Path) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    return info.value


def test_polygon_rule_refuses_a_bow_tie_and_keeps_simple_rings() -> None:
    square = [(40.0, -3.0), (40.001, -3.0), (40.001, -2.999), (40.0, -2.999)]
    assert polygon_problem(square) is None
    bow_tie = [square[0], square[2], square[1], square[3]]
    assert "intersects itself" in (polygon_problem(bow_tie) or "")
    assert "no area" in (polygon_problem([(40.0, -3.0), (40.001, -3.0), (40.002, -3.0)]) or "")
    assert "at least 3" in (polygon_problem(square[:2]) or "")
    assert "latitude" in (polygon_problem([(95.0, 0.0), *square[1:]]) or "")
    # a concave (U-shaped) ring is simple: valid
    u = [(0, 0), (0, 3), (3, 3), (3, 0), (2, 0), (2, 2), (1, 2), (1, 0)]
    assert polygon_problem([(40 + a * 1e-4, -3 + b * 1e-4) for a, b in u]) is None


def test_scenario_bow_tie_geofence_is_refused(tmp_path: Path) -> None:
    assert G1_POLYGON in BASE
    err = _error(_write(tmp_path, BASE.replace(G1_POLYGON, BOW_TIE)))
    assert (err.item, err.field) == ("geofences[0] (G1)", "polygon")
    assert "intersects itself" in err.message


@pytest.mark.parametrize(
    ("old", "new", "field", "fragment"),
    [
        ("{ east_m = 100.0,", "{ east_m = 1e12,", "waypoints[1].east_m", "+-500000 m"),
        (
            "{ east_m = 0.0, north_m = 0.0, alt_agl_m = 30.0 }",
            "{ east_m = 0.0, north_m = 0.0, alt_agl_m = -1e9 }",
            "waypoints[0].alt_agl_m",
            "above ground (ground at 600 m AMSL), got -1000000000.0",
        ),
        ("alt_amsl_m = 650.0", "alt_amsl_m = 25000.0", "waypoints[2].alt_amsl_m", "m AMSL"),
    ],
)
def test_implausible_positions_name_file_key_and_bounds(
    tmp_path: Path, old: str, new: str, field: str, fragment: str
) -> None:
    assert old in BASE
    path = _write(tmp_path, BASE.replace(old, new, 1))
    err = _error(path)
    assert (err.file, err.item, err.field) == (str(path), "operations[0] (A)", field)
    assert fragment in err.message, err.message
    assert str(path) in str(err) and field in str(err)


def test_implausible_geofence_radius_and_ground(tmp_path: Path) -> None:
    err = _error(_write(tmp_path, BASE.replace("radius_m = 40.0", "radius_m = 4e7")))
    assert err.field == "area.cylinder.radius_m" and "radius" in err.message
    err = _error(
        _write(
            tmp_path,
            BASE.replace("ground_elevation_amsl_m = 600.0", "ground_elevation_amsl_m = 1e9"),
        )
    )
    assert (err.item, err.field) == ("airspace", "ground_elevation_amsl_m")


@pytest.mark.parametrize("text", [DEEP, DEEP_TABLES])
def test_deep_nesting_is_one_error_in_every_loader(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str
) -> None:
    path = _write(tmp_path, text)
    err = _error(path)
    assert "nested deeper than 64 levels" in err.message
    for argv in (["scenario", "check", str(path)], ["config", "check", str(path)]):
        assert main(argv) == 2
        _out, errtext = capsys.readouterr()
        assert errtext.count("\n") == 1 and "nested deeper" in errtext, errtext
        assert "Traceback" not in errtext and "RecursionError" not in errtext
    tlog = tmp_path / "one.tlog"
    _one_record_tlog(tlog)
    assert main(["replay", str(tlog), "--scenario", str(path), "--no-progress"]) == 1
    _out, errtext = capsys.readouterr()
    assert "nested deeper" in errtext and "Traceback" not in errtext


def _one_record_tlog(path: Path) -> None:
    os.environ["MAVLINK20"] = "1"
    from pymavlink.dialects.v20 import common as mav

    from adapters.tlog import TlogWriter

    enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    hb = enc.heartbeat_encode(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, 129, 0, 4)
    with TlogWriter(path) as w:
        w.write(1_700_000_000.0, hb.pack(enc))


def test_deep_gauss_json_and_yaml_are_one_error(tmp_path: Path) -> None:
    deep_json = _write(tmp_path, '{"operations": ' + "[" * 5000 + "]" * 5000 + "}", "d.json")
    _write(tmp_path, "origin_latitude: 40.0\norigin_longitude: -3.0\n", "d.yaml")
    with pytest.raises(ScenarioError, match="nested deeper"):
        load_gauss(deep_json)
    deep_yaml = _write(tmp_path, "a: " + "[" * 5000 + "]" * 5000 + "\n", "e.yaml")
    with pytest.raises(ScenarioError, match="nested deeper"):
        load_any(deep_yaml)


def test_nesting_depth_is_counted_without_recursion() -> None:
    doc: list[object] = []
    for _ in range(100_000):
        doc = [doc]
    assert nesting_depth(doc, limit=64) == 65
    assert nesting_depth({"a": [1, {"b": 2}]}) == 3
    assert nesting_depth(5) == 0


def test_check_json_prints_an_error_document(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, BASE.replace("sys_id = 2", "sys_id = 1"))
    assert main(["scenario", "check", str(path), "--json"]) == 2
    out, err = capsys.readouterr()
    doc = json.loads(out)
    assert doc == {
        "error": {
            "file": str(path),
            "item": "operations[1] (B)",
            "field": "sys_id",
            "message": "1 is also used by A",
        }
    }
    assert err.count("\n") == 1
    assert main(["scenario", "check", str(tmp_path / "absent.toml"), "--json"]) == 2
    out, _ = capsys.readouterr()
    assert json.loads(out)["error"]["message"] == "the file does not exist"
    good = _write(tmp_path, BASE, "good.toml")
    for step in ("0", "abc", "1e-9", "nan"):
        assert main(["scenario", "check", str(good), "--json", "--step-s", step]) == 2
        out, _ = capsys.readouterr()
        assert json.loads(out)["error"]["field"] == "--step-s"


def test_check_json_prints_an_error_document_even_on_a_bug(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from gcs_utm.cli import scenario as scenario_cli

    def broken(*_args: object, **_kw: object) -> None:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(scenario_cli, "strategic_check", broken)
    good = _write(tmp_path, BASE, "good.toml")
    with pytest.raises(ZeroDivisionError):
        main(["scenario", "check", str(good), "--json"])
    out, _ = capsys.readouterr()
    assert "a bug" in json.loads(out)["error"]["message"]


def test_a_directory_is_reported_as_a_directory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scenario", "check", str(tmp_path)]) == 2
    _out, err = capsys.readouterr()
    assert "is a directory" in err and "does not exist" not in err
    assert main(["config", "check", str(tmp_path)]) == 2
    _out, err = capsys.readouterr()
    assert "is a directory" in err
    assert main(["replay", str(tmp_path), "--no-progress"]) == 2
    _out, err = capsys.readouterr()
    assert "is a directory" in err and "no such file" not in err


def test_gauss_yaml_is_the_entry_point_of_its_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    yaml_path = GAUSS / "paper_dev/madrid_geo_conflict.yaml"
    by_yaml = load_any(yaml_path, t0_s=100.0)
    by_json = load_gauss(GAUSS / "paper_dev/madrid_geo_conflict.json", t0_s=100.0)
    assert by_yaml == by_json
    assert main(["scenario", "check", str(yaml_path)]) == 0
    out, _ = capsys.readouterr()
    assert "madrid_geo_conflict" in out and "malformed" not in out


def test_gauss_yaml_naming_a_missing_json_names_the_key(tmp_path: Path) -> None:
    y = _write(tmp_path, "operations_json: nowhere\norigin_latitude: 40\n", "x.yaml")
    with pytest.raises(ScenarioError) as info:
        load_any(y)
    assert (info.value.field, info.value.file) == ("operations_json", str(y))
    assert "nowhere.json" in info.value.message


@pytest.mark.parametrize("speed", ["0", "-1", "nan", "inf", "fast"])
def test_speed_factor_must_be_positive(speed: str, capsys: pytest.CaptureFixture[str]) -> None:
    for cmd in (["run", "s.toml"], ["demo"], ["serve"]):
        with pytest.raises(SystemExit) as info:
            build_parser().parse_args([*cmd, "--speed", speed])
        assert info.value.code == 2
        _out, err = capsys.readouterr()
        assert "--speed: expected a positive number" in err
    assert build_parser().parse_args(["run", "s.toml", "--speed", "2.5"]).speed == 2.5
    if speed != "inf":  # replay reads inf as "max"
        with pytest.raises(SystemExit):
            build_parser().parse_args(["replay", "x.tlog", "--speed", speed])
        assert "expected a positive number or 'max'" in capsys.readouterr().err
    assert build_parser().parse_args(["replay", "x.tlog", "--speed", "max"]).speed is None


def test_a_yaml_alias_bomb_is_walked_in_linear_time(tmp_path: Path) -> None:
    """Ten levels, each repeating the one below ten times through aliases: 10**10 leaves if
    expanded, a few hundred containers in memory. Loading stays fast and fails on the
    missing origin, not on time or memory."""
    lines = ["l0: &l0 [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]"]
    for i in range(1, 11):
        lines.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 10) + "]")
    bomb = _write(tmp_path, "\n".join(lines) + "\n", "bomb.yaml")
    with pytest.raises(ScenarioError, match="operations_json"):
        load_any(bomb)
    shared: list[object] = [1, 2]
    for _ in range(40):
        shared = [shared] * 10
    assert nesting_depth(shared) == 41
