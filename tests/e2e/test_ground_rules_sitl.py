"""Issue 31 item 2 against the built-in vehicles (``sitl/``), as ``tests/autopilot``'s
``test_ground_px4.py`` and ``test_ground_reboot.py`` check it against real PX4 and ArduCopter.

A PX4-personality and an ArduCopter-personality ``sitl`` vehicle stand disarmed at the two
ends of a crossing, each with its crossing leg as mission, beside ``gcs-utm serve --headless
--auto-accept``. Both acquire GNSS for a few seconds after boot. Nothing is decided for them
on the ground: no recommendation, no threat, no mission replaced, no mode set. Then the
ArduCopter reboots on the ground (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: silent, a new boot whose
time_boot_ms starts from 0, its TCP connection dropped, GNSS acquired again): serve sees the
reboot and treats it as a new pre-flight, not an emergency.

With the same two vehicles armed and crossing at 15 m above ground, no plan serve generates
goes below the floor above their homes at arming (issue 31 item 3). And the threat lifecycle
with the built-in vehicles in a fast-time scenario run: a threat closes when the UAS's fix is
back, or when the UAS is on the ground.
"""

from __future__ import annotations

import asyncio
import math
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

import sitl
from gcs_utm.app import OperatorMode, RunOptions, run_scenario_blocking
from gcs_utm.settings import Settings
from tests.autopilot.closed_loop import Crossing, _config, below_floor, rows

pytestmark = [pytest.mark.network, pytest.mark.timeout(120)]

SPEED = 10.0
SCENARIOS = Path(__file__).resolve().parents[2] / "config" / "scenarios"
GROUND_M = 675.0
ORIGIN = (40.6597, -3.5969)
WATCH_S = 30.0  # simulated seconds watched on the ground, before and after the reboot


def _fly(path: Path, out_dir: Path, operator: str, duration_s: float) -> dict[str, Any]:
    """The scenario at ``path`` flown by the built-in vehicles in fast time, headless, for
    ``duration_s``: its run report."""
    options = RunOptions(
        speed=math.inf,
        headless=True,
        operator=operator,
        out_dir=out_dir,
        figures=False,
        duration_s=duration_s,
    )
    return run_scenario_blocking(path, Settings(), options).to_json()


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _specs(crossing: Crossing, gcs_port: int) -> list[sitl.VehicleSpec]:
    """A PX4 (sysid 1) and an ArduCopter (sysid 2) on the crossing's starts, each with its
    leg (above its start, then to its end at 8 m/s) as mission."""
    out = []
    for i, (autopilot, start, end) in enumerate(
        zip(("px4", "ardupilot"), crossing.starts(), crossing.ends(), strict=True)
    ):
        alt = GROUND_M + crossing.cruise_agl_m
        out.append(
            sitl.VehicleSpec(
                instance=i,
                autopilot=autopilot,
                home_lat_deg=start[0],
                home_lon_deg=start[1],
                home_alt_amsl_m=GROUND_M,
                mission=(
                    sitl.MissionItemSpec(lat_deg=start[0], lon_deg=start[1], alt_amsl_m=alt),
                    sitl.MissionItemSpec(
                        lat_deg=end[0], lon_deg=end[1], alt_amsl_m=alt, speed_mps=8.0
                    ),
                ),
                gcs_port=gcs_port,
                bind_port=0 if autopilot == "px4" else None,
                tcp_port=0 if autopilot == "ardupilot" else None,
                gnss_fix_after_s=4.0,
            )
        )
    return out


def _serve(cfg: Path, db: Path, log_path: Path) -> subprocess.Popen[bytes]:
    with log_path.open("wb") as log:
        return subprocess.Popen(
            [sys.executable, "-m", "gcs_utm", "-v", "serve", "--headless", "--auto-accept",
             "--config", str(cfg), "--db", str(db), "--speed", str(SPEED)],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
        )  # fmt: skip


def _stop(serve: subprocess.Popen[bytes] | None) -> None:
    if serve is not None and serve.poll() is None:
        serve.terminate()
        serve.wait(timeout=30)


async def _watch(fleet: sitl.Fleet, sim_s: float, modes: list[str]) -> None:
    end = time.monotonic() + sim_s / SPEED
    while time.monotonic() < end:
        modes.extend(v.mode for v in fleet.vehicles)
        await asyncio.sleep(0.05)


async def _until(cond: object, timeout_s: float, what: str, log: Path) -> None:
    end = time.monotonic() + timeout_s
    while not cond():  # type: ignore[operator]
        assert time.monotonic() < end, f"{what}\n" + log.read_text(errors="replace")[-3000:]
        await asyncio.sleep(0.1)


async def test_disarmed_sitl_vehicles_get_no_decision_and_a_reboot_is_a_new_preflight(
    tmp_path: Path,
) -> None:
    crossing = Crossing(origin=ORIGIN, ground_amsl_m=GROUND_M)
    port = _free_udp_port()
    sim = sitl.SimTime(SPEED)
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    serve: subprocess.Popen[bytes] | None = None
    modes: list[str] = []
    async with sitl.Fleet(_specs(crossing, port), sim) as fleet:
        px4, copter = fleet.vehicle(1), fleet.vehicle(2)
        missions = [v.mission for v in fleet.vehicles]
        cfg = _config(
            tmp_path / "serve.toml",
            crossing,
            [f"udpin:127.0.0.1:{port}", f"tcp:127.0.0.1:{copter.tcp_port}"],
        )
        try:
            serve = _serve(cfg, db, log_path)
            await _until(
                lambda: len(rows(db, "SELECT id FROM operations")) >= 2,
                40.0,
                "the two missions were not filed",
                log_path,
            )
            await _watch(fleet, WATCH_S, modes)
            before_reboot = len(modes)
            assert copter.commands._command_table()[246](None, None, [1.0] + [0.0] * 6) == 0  # type: ignore[arg-type]
            await _until(
                lambda: "sysid 2: rebooted" in log_path.read_text(errors="replace"),
                30.0,
                "the reboot was not seen",
                log_path,
            )
            assert copter.reboots == 1
            await _watch(fleet, WATCH_S, modes)
            assert serve.poll() is None, "gcs-utm serve exited"
        finally:
            _stop(serve)
        after = [v.mission for v in fleet.vehicles]
        armed = [v.armed for v in fleet.vehicles]
    text = log_path.read_text(errors="replace")
    tail = text[-4000:]
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for vehicles on the ground: {recs}\n{tail}"
    assert after == missions, f"a mission was replaced\n{tail}"
    assert not any(armed)
    assert before_reboot > 0 and "MISSION" not in modes, f"mission mode set on the ground\n{tail}"
    threats = rows(db, "SELECT kind FROM threats")
    assert threats == [], f"threats for vehicles on the ground: {threats}\n{tail}"
    filed = rows(db, "SELECT operation_id FROM flight_plans WHERE version = 1")
    assert len(filed) == 2, filed
    for sys_id in (1, 2):  # the home is the one after the fix
        fix = text.find(f"sysid {sys_id}: fix")
        home = text.find(f"sysid {sys_id}: home ")
        assert 0 <= fix < home, f"sysid {sys_id}: home before its fix\n{tail}"
    assert px4.reboots == 0


def test_threats_close_when_the_fix_is_back_and_when_the_uas_landed(tmp_path: Path) -> None:
    """Use case 2 (UAS1 jammed for 120 s, commanded down) with UAS2 jammed for 20 s, fast
    time, the built-in vehicles: UAS2's GNSS_DEGRADATION closes when its fix is back (its
    JAMMING_ATTACK does not: nothing UAS2 reports says the jammer is gone), and UAS1's
    threats close once it is on the ground (disarmed), each with its reason."""
    text = (SCENARIOS / "use_case_2.toml").read_text()
    text += (
        '\n[[events]]\nat_s = 12.0\nkind = "gnss_jamming"\nuas = "UAS2"\nduration_s = 20.0\n'
        "value = 0.6\n"
    )
    path = tmp_path / "use_case_2_two_jammed.toml"
    path.write_text(text)
    report = _fly(path, tmp_path, OperatorMode.AUTO_ACCEPT, 150.0)
    closed = {
        (t["kind"], t["uas"][0]): t["message"] for t in report["threats"] if t["status"] == "closed"
    }
    assert "closed: GNSS fix back" in closed[("GNSS_DEGRADATION", "UAS2")], closed
    assert "closed: UAS1 is on the ground" in closed[("JAMMING_ATTACK", "UAS1")], closed
    assert "closed: UAS1 is on the ground" in closed[("GNSS_DEGRADATION", "UAS1")], closed


async def test_plans_generated_for_flying_sitl_vehicles_keep_above_the_floor(
    tmp_path: Path,
) -> None:
    """As ``test_px4_closed_loop.py`` / ``test_ardupilot_closed_loop.py`` (closed_loop.
    below_floor): once filed, the two vehicles are armed and started by their pilots and
    cross at 15 m above ground; the
    loss of separation is resolved by serve (auto-accept), and no waypoint of a plan it
    generates lies below the floor (10 m) above the vehicle's home at arming."""
    crossing = Crossing(origin=ORIGIN, ground_amsl_m=GROUND_M, cruise_agl_m=15.0)
    port = _free_udp_port()
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    serve: subprocess.Popen[bytes] | None = None
    async with sitl.Fleet(_specs(crossing, port), sitl.SimTime(SPEED)) as fleet:
        cfg = _config(
            tmp_path / "serve.toml",
            crossing,
            [f"udpin:127.0.0.1:{port}", f"tcp:127.0.0.1:{fleet.vehicle(2).tcp_port}"],
        )
        try:
            serve = _serve(cfg, db, log_path)
            await _until(
                lambda: len(rows(db, "SELECT id FROM operations")) >= 2,
                40.0,
                "the two missions were not filed",
                log_path,
            )
            for v in fleet.vehicles:  # the pilots start their missions
                assert v.arm() == 0 and v.commands.request_mode("MISSION") == 0
            await _until(
                lambda: len(rows(db, "SELECT id FROM recommendations")) >= 1,
                60.0,
                "no recommendation for the crossing",
                log_path,
            )
            await _watch(fleet, 20.0, [])
            assert serve.poll() is None, "gcs-utm serve exited"
        finally:
            _stop(serve)
    tail = log_path.read_text(errors="replace")[-4000:]
    assert below_floor(db) == [], tail


_RETURN_HOME_SCENARIO = """
[scenario]
name = "return_home_lands"
description = "A multirotor low on battery, no landing site: it returns home and lands there"
duration_s = 130.0

[airspace]
origin_lat_deg = 40.6597
origin_lon_deg = -3.5969
ground_elevation_amsl_m = 675.0

[[operations]]
id = "UAS1"
sys_id = 1
priority = 1
conops = "survey"
operator = "pilot-uas1"
icao24 = "346617"
vehicle = "multirotor"
autopilot = "{autopilot}"
cruise_speed_mps = 5.0
flight_geometry_m = 8.0
operational_volume_m = 15.0
max_climb_rate_mps = 2.0
endurance_s = 1200.0
home = {{ east_m = 0.0, north_m = 0.0, alt_agl_m = 0.0 }}
waypoints = [
    {{ east_m = 60.0, north_m = 0.0, alt_agl_m = 30.0 }},
    {{ east_m = 900.0, north_m = 0.0, alt_agl_m = 30.0 }},
]

[[events]]
at_s = 10.0
kind = "battery_drop"
uas = "UAS1"
value = 20.0
reason = "battery below the 25 % reserve"
"""


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_return_home_lands_at_home_and_its_threat_closes_on_the_ground(
    tmp_path: Path, autopilot: str
) -> None:
    """A multirotor below its battery reserve with no landing site is sent home (auto-accept,
    fast time, the built-in vehicles): its mission ends with a NAV_LAND at home, so it lands
    there, disarms, and LACK_OF_BATTERY closes because the UAS is on the ground. (With a
    waypoint at ground level instead, the vehicle hovered over home armed, and the threat
    stayed open: return_home was proposed again every 30 s until a LAND command ended it.)"""
    path = tmp_path / "return_home.toml"
    path.write_text(_RETURN_HOME_SCENARIO.format(autopilot=autopilot))
    report = _fly(path, tmp_path, OperatorMode.AUTO_ACCEPT, 130.0)
    # return_home flown to the ground: no LAND command needed in the end
    [rec] = report["recommendations"]
    assert (rec["maneuver"], rec["state"]) == ("return_home", "applied"), rec["history"]
    threats = [t for t in report["threats"] if t["kind"] == "LACK_OF_BATTERY"]
    threat = threats[-1]
    assert threat["status"] == "closed", threat
    assert threat["message"].endswith(
        ("closed: operation UAS1 landed", "closed: UAS1 is on the ground")
    ), threat


_OTHER_LANDS_SCENARIO = """
[scenario]
name = "other_uas_lands"
description = "Two multirotors fly side by side 30 m apart, 12 m up; the second one lands"
duration_s = 70.0

[airspace]
origin_lat_deg = 40.6597
origin_lon_deg = -3.5969
ground_elevation_amsl_m = 675.0
{operations}
[[events]]
at_s = 25.0
kind = "motor_failure"
uas = "UAS2"
reason = "UAS2 lands at once"
"""

_SIDE_BY_SIDE_OPERATION = """
[[operations]]
id = "UAS{k}"
sys_id = {k}
priority = 1
conops = "survey"
operator = "pilot-uas{k}"
icao24 = "34661{k}"
vehicle = "multirotor"
autopilot = "{autopilot}"
cruise_speed_mps = 5.0
flight_geometry_m = 8.0
operational_volume_m = 10.0
max_climb_rate_mps = 2.0
home = {{ east_m = 0.0, north_m = {north}, alt_agl_m = 0.0 }}
waypoints = [
    {{ east_m = 0.0, north_m = {north}, alt_agl_m = 12.0 }},
    {{ east_m = 600.0, north_m = {north}, alt_agl_m = 12.0 }},
]
"""


def test_a_loss_of_separation_closes_when_the_other_sitl_uas_lands(tmp_path: Path) -> None:
    """As ``test_threats_close.py::test_a_loss_of_separation_closes_when_the_other_copter_
    lands`` on two ArduCopters: a PX4 and an ArduCopter built-in vehicle fly side by side 30 m
    apart 12 m above the ground (a loss of separation, open while both fly; the landing never
    clears the vertical minimum; no operator answers); the second one lands (a motor failure:
    it comes down where it is and disarms). The loss of separation closes because the other
    UAS is on the ground, with that reason."""
    operations = "".join(
        _SIDE_BY_SIDE_OPERATION.format(k=k, autopilot=autopilot, north=north)
        for k, autopilot, north in ((1, "px4", 0.0), (2, "ardupilot", 30.0))
    )
    path = tmp_path / "other_uas_lands.toml"
    path.write_text(_OTHER_LANDS_SCENARIO.format(operations=operations))
    report = _fly(path, tmp_path, OperatorMode.NONE, 70.0)
    los = [t for t in report["threats"] if t["kind"] == "LOSS_OF_SEPARATION"]
    assert los, report["threats"]
    last = los[-1]
    assert last["status"] == "closed", los
    assert sorted(last["uas"]) == ["UAS1", "UAS2"], last
    assert last["message"].endswith(
        ("closed: operation UAS2 landed", "closed: UAS2 is on the ground")
    ), last
    final = {t["id"]: t["status"] for t in los}  # (the report lists each state it went through)
    assert set(final.values()) == {"closed"}, los
