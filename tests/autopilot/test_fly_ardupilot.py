"""``gcs-utm run SCENARIO --external --fly`` on real ArduPilot 4.6 SITL: two ArduCopters, and
one ArduPlane.

Each copter starts on the ground at its operation's home and sends MAVLink on SERIAL0 to the
ground service's UDP port (``--serial0 udpclient:127.0.0.1:14550``, as a telemetry radio or
mavlink-router would); the test reads ArduPilot's own positions on SERIAL1 (TCP 5762+10i).
The run uploads each filed plan (ArduPilot's layout: seq 0 home, verified by readback),
switches to GUIDED, arms (refused for a while after boot: retried), takes off to the first
waypoint's height above home and switches to AUTO at the first waypoint's time. The ArduPlane
is armed in TAKEOFF mode (ArduPlane takes NAV_TAKEOFF as a command only on quadplanes) and,
30 m up, sent to loiter at its first waypoint (DO_REPOSITION) until then. ArduPilot's own
positions must pass every waypoint, and the report must say uploaded, verified, armed and
started for each vehicle.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.pilot import PilotLink, Sample, local_m, offset_deg

SPEED = 5.0  # ArduPilot --speedup; run --speed matches it
LAT0, LON0, GROUND_M, _HEADING = ARDUPILOT_DEFAULT_HOME
START_S = 75.0  # first waypoint time: arming is refused ~20-30 s (sim) after boot
Plans = dict[str, tuple[int, tuple[float, float], list[tuple[float, float, float]]]]
# (sys_id, home east/north m, waypoints east/north/alt AGL m): two copters well apart
PLANS: Plans = {
    "COPTER1": (1, (0.0, 0.0), [(0.0, 0.0, 20.0), (120.0, 0.0, 20.0), (120.0, 90.0, 20.0)]),
    "COPTER2": (2, (0.0, -200.0), [(0.0, -200.0, 30.0), (-120.0, -200.0, 30.0)]),
}
# one ArduPlane: north from its runway, then west; its volume holds its waiting loiter
PLANE_PLANS: Plans = {
    "PLANE": (1, (0.0, 0.0), [(0.0, 500.0, 60.0), (-800.0, 500.0, 60.0), (-800.0, -300.0, 60.0)]),
}
PLANE_TOLERANCE_M = 40.0
WAYPOINT_TOLERANCE_M = 8.0  # horizontal (WPNAV_RADIUS 2 m, samples at 10 Hz)
ALTITUDE_TOLERANCE_M = 3.0


def _scenario(path: Path, plans: Plans, vehicle: str) -> Path:
    plane = vehicle == "fixed_wing"
    ops = []
    for uas, (sys_id, home, wps) in plans.items():
        points = ", ".join(f"{{ east_m = {e}, north_m = {n}, alt_agl_m = {a} }}" for e, n, a in wps)
        ops.append(
            f"""
[[operations]]
id = "{uas}"
sys_id = {sys_id}
priority = {sys_id}
vehicle = "{vehicle}"
autopilot = "ardupilot"
icao24 = "c0ffa{sys_id}"
conops = "survey"
operator = "pilot-{uas.lower()}"
cruise_speed_mps = {22.0 if plane else 6.0}
flight_geometry_m = {20.0 if plane else 5.0}
operational_volume_m = {120.0 if plane else 10.0}
endurance_s = 1200.0
max_climb_rate_mps = {4.0 if plane else 2.0}
start_s = {START_S}
home = {{ east_m = {home[0]}, north_m = {home[1]}, alt_agl_m = 0.0 }}
waypoints = [{points}]
"""
        )
    path.write_text(
        f"""
[scenario]
name = "fly_ardupilot"
description = "two ArduCopters fly their filed plans (--external --fly)"
duration_s = 160.0

[airspace]
origin_lat_deg = {LAT0}
origin_lon_deg = {LON0}
ground_elevation_amsl_m = {GROUND_M}
"""
        + "".join(ops)
    )
    return path


def _closest_m(
    samples: list[Sample], east_m: float, north_m: float, alt_amsl_m: float, alt_tol_m: float
) -> float:
    """Horizontal distance of the closest pass within ``alt_tol_m`` of the altitude."""
    best = math.inf
    for s in samples:
        e, n = local_m(LAT0, LON0, s.lat_deg, s.lon_deg)
        if abs(s.alt_amsl_m - alt_amsl_m) < alt_tol_m:
            best = min(best, math.hypot(e - east_m, n - north_m))
    return best


@pytest.mark.timeout(240)
def test_two_ardupilot_copters_fly_their_plans(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    _fly(ardupilot, tmp_path, PLANS, "copter")


@pytest.mark.timeout(240)
def test_ardupilot_plane_flies_its_plan(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    _fly(ardupilot, tmp_path, PLANE_PLANS, "plane")


def _fly(ardupilot: Callable[..., SitlProcess], tmp_path: Path, plans: Plans, vehicle: str) -> None:
    pilots = {}
    for uas, (sys_id, home, _wps) in plans.items():
        lat, lon = offset_deg(LAT0, LON0, *home)
        i = sys_id - 1
        ardupilot(
            instance=i,
            vehicle=vehicle,
            home=(lat, lon, GROUND_M, 0.0),
            speed=SPEED,
            extra_args=("--serial0", "udpclient:127.0.0.1:14550"),
        )
        wait_tcp_listening(5762 + 10 * i)
        pilots[uas] = PilotLink(i, autopilot="ardupilot", tcp_port=5762 + 10 * i)
    try:
        for pilot in pilots.values():
            pilot.wait_ready()  # streaming positions before the run starts
        kind = "fixed_wing" if vehicle == "plane" else "multirotor"
        _run_and_check(pilots, _scenario(tmp_path / "fly_ardupilot.toml", plans, kind), tmp_path)
    finally:
        for pilot in pilots.values():
            pilot.close()


def _run_and_check(pilots: dict[str, PilotLink], scenario: Path, tmp_path: Path) -> None:
    out_dir = tmp_path / "runs"
    t0 = time.monotonic()
    with subprocess.Popen(
        [sys.executable, "-m", "gcs_utm", "run", str(scenario), "--external", "--fly",
         "--auto-accept", "--headless", "--no-figures", "--speed", str(SPEED),
         "--out", str(out_dir)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
    ) as run:  # fmt: skip
        while run.poll() is None and time.monotonic() - t0 < 200.0:
            for pilot in pilots.values():
                pilot.poll(0.02)
        if run.poll() is None:
            run.kill()
        log = (run.stdout.read() if run.stdout else "")[-6000:]
    print(f"run: {time.monotonic() - t0:.0f} s wall")
    assert run.returncode == 0, log
    report = json.loads((out_dir / "fly_ardupilot.json").read_text())
    fly = {f["uas"]: f for f in report["fly"]}
    threats = [(t["kind"], t["uas"], t["detected_at_s"]) for t in report["threats"]]
    print(f"threats: {threats}")
    for uas in pilots:
        f = fly[uas]
        assert not f["error"], f"{uas}: {f}\n{log}"
        assert f["uploaded"] and f["verified"] and f["armed"] and f["started"], f"{f}\n{log}"
        print(f"{uas}: mission started {f['late_s']} s after its first waypoint's time")
    plans = {**PLANS, **PLANE_PLANS}
    missed = []
    for uas, pilot in pilots.items():
        assert pilot.samples, f"{uas}: no positions from ArduPilot on SERIAL1"
        top_m = max(s.alt_amsl_m for s in pilot.samples) - GROUND_M
        print(f"{uas}: {len(pilot.samples)} positions, highest {top_m:.1f} m above ground")
        tolerance = PLANE_TOLERANCE_M if uas == "PLANE" else WAYPOINT_TOLERANCE_M
        alt_tol_m = 10.0 if uas == "PLANE" else ALTITUDE_TOLERANCE_M
        for e, n, a in plans[uas][2]:
            miss = _closest_m(pilot.samples, e, n, GROUND_M + a, alt_tol_m)
            print(f"{uas}: waypoint ({e}, {n}, {a} AGL) passed at {miss:.1f} m")
            if miss >= tolerance:
                missed.append(f"{uas}: ({e}, {n}, {a}) missed by {miss:.1f} m")
    assert not missed, f"{missed}\n{log}"
