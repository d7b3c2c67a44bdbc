"""`gcs-utm replay` of ADS-B receiver captures shipped in tests/data: the SBS-1 capture alone
and beside the ArduSub tlog (merged by time, one report), the real Beast capture (timed by its
12 MHz MLAT counter), an AVR capture with MLAT prefixes, and bad input."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from adapters.adsb.config import AdsbConfig
from gcs_utm.cli import main
from gcs_utm.cli.replay import ReplayError, replay_paths
from gcs_utm.geo import haversine_m
from tests.adsb.encode import CSV_T0_S, SBS_FLIGHTS, SBS_T0_S, csv_frames

DATA = Path(__file__).resolve().parents[1] / "data"
SBS = DATA / "adsb" / "synthetic_near_ardusub.sbs"
BEAST = DATA / "adsb" / "traffic_sample_dump1090_beast.bin"
ARDUSUB = DATA / "tlog" / "ardusub_log_tools_small.tlog"
FLOATPLANE, AIRLINER = (f"icao:{f.icao}" for f in SBS_FLIGHTS)

pytestmark = pytest.mark.data


def _cli(tmp_path: Path, *args: str) -> tuple[int, dict[str, object]]:
    out = tmp_path / "r.json"
    code = main(["replay", *args, "--report", str(out), "--no-progress"])
    return code, json.loads(out.read_text()) if out.exists() else {}


def test_sbs_capture_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, r = _cli(tmp_path, str(SBS))
    assert code == 0
    assert "480 ADS-B positions" in capsys.readouterr().out
    assert set(r["tracks"]) == {FLOATPLANE, AIRLINER}  # type: ignore[arg-type]
    (feed,) = r["counters"]["adsb_feeds"].values()  # type: ignore[index]
    assert (feed["frames"], feed["positions"], feed["rejects"]) == (1080, 480, 0)
    assert feed["untimed_lines"] == 0  # every line carries its UTC date/time
    # times are the lines' own: positions from 17:15:45 to 17:19:44.31 UTC
    assert r["duration"]["first_t_s"] == pytest.approx(SBS_T0_S)  # type: ignore[index]
    assert r["duration"]["duration_s"] == pytest.approx(239.31, abs=0.01)  # type: ignore[index]
    for flight in SBS_FLIGHTS:
        t = r["tracks"][f"icao:{flight.icao}"]  # type: ignore[index]
        assert t["updates"] == 240 and not t["cooperative"]
        lat, lon = flight.at(239.0)
        last = t["last_position"]
        # the tracker's filtered estimate of 1e-5 degree positions: within 15 m (measured:
        # 7.4 m for the airliner at 221 m/s)
        assert haversine_m(lat, lon, last["lat_deg"], last["lon_deg"]) < 15.0
        assert last["alt_amsl_m"] == pytest.approx(flight.alt_ft * 0.3048, abs=1.0)
        assert t["max_ground_speed_mps"] == pytest.approx(flight.speed_kt * 1852 / 3600, rel=0.05)
    assert r["inputs"] == [{"path": str(SBS), "kind": "sbs", "feed": SBS.stem}]


def test_sbs_capture_beside_the_tlog_merged_by_time(tmp_path: Path) -> None:
    code, r = _cli(tmp_path, str(ARDUSUB), str(SBS))
    assert code == 0
    # the tlog's own report (test_replay.py), plus the aircraft
    assert r["records"] == 35912
    assert set(r["tracks"]) == {"sysid:1", FLOATPLANE, AIRLINER}  # type: ignore[arg-type]
    assert r["tracks"]["sysid:1"]["updates"] == 792  # type: ignore[index]
    assert r["counters"]["adsb_capture_measurements"] == 480  # type: ignore[index]
    assert r["duration"]["duration_s"] == pytest.approx(263.43, abs=0.01)  # type: ignore[index]
    assert r["frame"]["epsg"] == 32610  # type: ignore[index]  # from the ROV's first position
    kinds = [i["kind"] for i in r["inputs"]]  # type: ignore[attr-defined]
    assert kinds == ["tlog", "sbs"]
    # the aircraft were tracked while the ROV was: their first updates fall in the tlog's span
    t0 = r["duration"]["first_t_s"]  # type: ignore[index]
    assert 0.0 < r["tracks"][FLOATPLANE]["first_t_s"] - t0 < 5.0  # type: ignore[index]


def test_beast_capture_timed_by_its_mlat_counter(tmp_path: Path) -> None:
    config = tmp_path / "toulouse.toml"
    config.write_text(
        "[adsb]\nreceiver_position_known = true\nreceiver_lat_deg = 43.6\nreceiver_lon_deg = 1.44\n"
    )
    start = 1_581_500_000.0
    code, r = _cli(
        tmp_path, str(BEAST), "--config", str(config), "--adsb-start", "2020-02-12T09:33:20Z"
    )
    assert code == 0
    assert set(r["tracks"]) == {"icao:48520a"}  # type: ignore[arg-type]
    t = r["tracks"]["icao:48520a"]  # type: ignore[index]
    assert t["updates"] == 4 and t["last_position"]["alt_amsl_m"] > 11_000.0
    (feed,) = r["counters"]["adsb_feeds"].values()  # type: ignore[index]
    assert (feed["frames"], feed["not_adsb"], feed["positions"]) == (239, 216, 4)
    assert feed["mlat_resets"] == 0
    # MLAT times from the given start: the positions lie in the 24 s capture, 7.83 s apart
    assert start <= r["duration"]["first_t_s"] < start + 24.0  # type: ignore[index]
    assert t["last_t_s"] - t["first_t_s"] == pytest.approx(6.88, abs=0.01)


def test_beast_capture_without_receiver_position_has_no_pair(tmp_path: Path, capsys) -> None:
    # four positions that never form an even/odd pair: nothing to track, said in one line
    code, _ = _cli(tmp_path, str(BEAST))
    assert code == 1
    assert "no ADS-B position in the capture" in capsys.readouterr().err


def test_avr_capture_with_mlat_prefixes(tmp_path: Path) -> None:
    path = tmp_path / "feed.avr"
    path.write_text("".join(f"@{round((t - CSV_T0_S) * 12e6):012X}{h};\n" for t, h in csv_frames()))
    adsb = AdsbConfig(receiver_position_known=True, receiver_lat_deg=51.99, receiver_lon_deg=4.375)
    r = asyncio.run(replay_paths([path], adsb=adsb, adsb_start_t_s=CSV_T0_S))
    t = r["tracks"]["icao:4ca7e9"]
    assert t["updates"] == 600
    assert r["duration"]["first_t_s"] == pytest.approx(CSV_T0_S, abs=1e-6)
    assert r["duration"]["last_t_s"] == pytest.approx(CSV_T0_S + 599.0, abs=1e-6)


def test_bad_inputs_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path / "missing.sbs"), "--no-progress"]) == 2
    assert "no such file" in capsys.readouterr().err
    other = tmp_path / "notes.txt"
    other.write_text("hello")
    assert main(["replay", str(SBS), str(other), "--no-progress"]) == 2
    assert "unknown kind: expected .tlog, .sbs, .avr, .bin" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ReplayError, match=r"is a directory without any \.tlog or ADS-B"):
        asyncio.run(replay_paths([empty]))
    bad = tmp_path / "feed.sbs"
    bad.write_text("MSG,3,1,1,A1B2C3,1,,,,,,3000,,,47.4,8.5,,,0,0,0,0\n")
    bad.with_name("feed.sbs.times").write_text("1700000000000000 9999 1\n")
    with pytest.raises(ReplayError, match=r"feed.sbs.times: line 1: end offset 9999 outside"):
        asyncio.run(replay_paths([bad]))
