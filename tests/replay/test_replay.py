"""`gcs-utm replay`: the real ArduSub recording, a synthetic two-vehicle encounter, corrupt
input, pacing and the CLI."""

from __future__ import annotations

import asyncio
import dataclasses
import json
from pathlib import Path

import pytest
from replay_helpers import ALT0, CONVERGING, LAT0, LON0, MEET_S, T0_S, write_tlog

from adapters.mavlink import MavlinkConfig
from gcs_utm.cli import main
from gcs_utm.cli.replay import ReplayConfig, ReplayError, parse_speed, replay_file
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Operation,
    OperationId,
    SysId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.settings import Settings

DATA = Path(__file__).resolve().parents[1] / "data" / "tlog"
ARDUSUB = DATA / "ardusub_log_tools_small.tlog"


def _run(path: Path, **kw: object) -> dict[str, object]:
    return asyncio.run(replay_file(path, **kw))  # type: ignore[arg-type]


@pytest.mark.data
def test_real_ardusub_tlog_through_the_cli(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "r.json"
    assert main(["replay", str(ARDUSUB), "--report", str(out), "--no-progress"]) == 0
    assert "35912 records" in capsys.readouterr().out
    r = json.loads(out.read_text())
    # figures measured with the tlog adapter on this file (docs/formats.md)
    assert r["records"] == 35912
    assert r["duration"]["duration_s"] == pytest.approx(263.43, abs=0.01)
    assert r["counters"]["corrupt_records"] == 4
    assert r["counters"]["tlog"]["skipped_bytes"] == 315
    [v] = r["vehicles"]
    assert (v["sys_id"], v["autopilot"], v["positions"]) == (1, "ardupilot", 792)
    assert v["first_position"]["lat_deg"] == pytest.approx(48.386, abs=1e-3)
    assert v["first_position"]["lon_deg"] == pytest.approx(-124.631, abs=1e-3)
    # its one HOME_POSITION, through the live hub's handler table: the ROV's home at the surface
    home = {"lat_deg": 48.3861417, "lon_deg": -124.630573, "alt_amsl_m": 0.16}
    assert v["home"] == pytest.approx(home)
    assert v["last_height_above_home_m"] == pytest.approx(0.07, abs=0.005)
    assert r["frame"]["epsg"] == 32610  # UTM 10N, from the first position
    track = r["tracks"]["sysid:1"]
    assert track["updates"] == 792 and track["cooperative"] is False
    assert sum(r["counters"]["rejected_measurements"].values()) == 0
    # an ROV at the surface drifting: tens of metres, not kilometres
    assert 1.0 < track["distance_m"] < 500.0
    # the live monitoring service's cycles: one a second from the first record (0 .. 263 s),
    # and the last one at the last record
    assert r["counters"]["monitoring_cycles"] == 265
    assert r["threats"] == []  # no operations: nothing for Monitoring to watch
    assert r["counters"]["handler_errors"] == 0


def _operations() -> list[Operation]:
    ops = []
    for leg in CONVERGING:
        wps = []
        for dt in (0.0, 20.0, 40.0):
            lat, lon, alt = leg.at(dt)
            wps.append(Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=alt, t_s=T0_S + dt))
        op_id = OperationId(f"op-{leg.sys_id}")
        ops.append(
            Operation(
                id=op_id,
                icao24=None,
                sys_id=SysId(leg.sys_id),
                priority=1,
                plan=FlightPlan(operation_id=op_id, version=1, waypoints=tuple(wps)),
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=10.0,
                flight_geometry_m=15.0,
                operational_volume_m=30.0,
            )
        )
    return ops


def test_two_unknown_vehicles_are_intruder_tracks_without_threats(tmp_path: Path) -> None:
    path = tmp_path / "enc.tlog"
    n = write_tlog(path)
    r = _run(path)
    assert [v["sys_id"] for v in r["vehicles"]] == [1, 2]  # type: ignore[index]
    assert all(v["autopilot"] == "px4" for v in r["vehicles"])  # type: ignore[attr-defined]
    assert [v["positions"] for v in r["vehicles"]] == [n, n]  # type: ignore[attr-defined]
    tracks = r["tracks"]
    assert set(tracks) == {"sysid:1", "sysid:2"}  # type: ignore[arg-type]
    for tid in ("sysid:1", "sysid:2"):
        t = tracks[tid]  # type: ignore[index]
        assert t["cooperative"] is False and t["updates"] == n
        # 40 s at 10 m/s, sampled at 5 Hz: ~390 m flown (filter noise adds a little)
        assert t["distance_m"] == pytest.approx(390.0, rel=0.05)
    # Monitoring watches operations; two intruders near no operation raise nothing
    assert r["threats"] == []


def test_two_operations_converging_raise_loss_of_separation(tmp_path: Path) -> None:
    path = tmp_path / "enc.tlog"
    write_tlog(path)
    config = ReplayConfig(
        frame=LocalFrame(LAT0, LON0, ground_elevation_amsl_m=ALT0), operations=_operations()
    )
    r = _run(path, config=config)
    assert set(r["tracks"]) == {"op-1", "op-2"}  # type: ignore[arg-type]
    assert all(t["cooperative"] for t in r["tracks"].values())  # type: ignore[attr-defined]
    los = [t for t in r["threats"] if t["kind"] == "LOSS_OF_SEPARATION"]  # type: ignore[attr-defined]
    assert len(los) == 1, r["threats"]
    th = los[0]
    assert sorted(th["uas"]) == ["op-1", "op-2"]
    # predicted ahead: raised well before they meet (horizon 60 s), with a near-zero approach
    assert th["first_t_s"] < T0_S + MEET_S - 10.0
    assert th["min_closest_approach_m"] < 10.0
    assert r["counters"]["rejected_measurements"]["unassociated"] == 0  # type: ignore[index]


def test_the_replay_checks_signatures_as_a_live_link_does(tmp_path: Path) -> None:
    """Replayed records go through the live MAVLink hub, its checks included: with a signing
    key for system id 1 ([mavlink] signing_keys), the recording's unsigned frames of sysid 1
    are dropped as a live link drops them; sysid 2 (no key) is tracked."""
    path = tmp_path / "enc.tlog"
    n = write_tlog(path)
    keyed = MavlinkConfig(signing_keys={"1": "00" * 32})
    config = ReplayConfig(settings=dataclasses.replace(Settings(), mavlink=keyed))
    r = _run(path, config=config)
    assert set(r["tracks"]) == {"sysid:2"}  # type: ignore[arg-type]
    assert [(v["sys_id"], v["positions"]) for v in r["vehicles"]] == [(2, n)]  # type: ignore[attr-defined]


def test_corrupt_records_are_skipped_and_counted(tmp_path: Path) -> None:
    good = tmp_path / "good.tlog"
    n = write_tlog(good, duration_s=10.0)
    data = bytearray(good.read_bytes())
    # flip a payload byte in 5 records spread over the file, and add garbage in the middle
    step = len(data) // 6
    for k in range(1, 6):
        data[k * step] ^= 0x5A
    mid = len(data) // 2
    data[mid:mid] = b"\x00garbage\xfe\xfd\x01" * 3
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    r = _run(bad)
    c = r["counters"]
    assert c["corrupt_records"] >= 5  # type: ignore[index]
    assert c["tlog"]["skipped_bytes"] > 0  # type: ignore[index]
    assert c["handler_errors"] == 0  # type: ignore[index]
    positions = sum(v["positions"] for v in r["vehicles"])  # type: ignore[attr-defined]
    assert 2 * n - 8 <= positions < 2 * n  # at most the damaged records are lost


def test_not_a_tlog_is_one_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    junk = tmp_path / "junk.tlog"
    junk.write_bytes(b"this is not a tlog\n" * 100)
    with pytest.raises(ReplayError, match="no valid tlog record"):
        _run(junk)
    assert main(["replay", str(junk), "--no-progress", "--report", str(tmp_path / "x.json")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no valid tlog record" in err[0]
    assert not (tmp_path / "x.json").exists()
    assert main(["replay", str(tmp_path / "missing.tlog"), "--no-progress"]) == 2
    assert "no such file" in capsys.readouterr().err


def test_speed_factor_paces_on_record_time(tmp_path: Path) -> None:
    path = tmp_path / "enc.tlog"
    write_tlog(path, duration_s=8.0)
    fast = _run(path)
    paced = _run(path, speed=10.0)  # ~7.8 s of records -> ~0.78 s
    # paced on record time / 10 (not 1x: 7.8 s; a loaded machine adds CPU time to both),
    # while "max" waits for nothing
    assert 0.7 <= paced["wall_s"] < 4.0  # type: ignore[operator]
    assert fast["wall_s"] < paced["wall_s"]  # type: ignore[operator]
    assert paced["tracks"].keys() == fast["tracks"].keys()  # type: ignore[attr-defined]


def test_parse_speed() -> None:
    assert parse_speed("max") is None
    assert parse_speed("2.5") == 2.5
    for bad in ("-1", "fast", "nan"):
        with pytest.raises(Exception, match="positive number or 'max'"):
            parse_speed(bad)
