"""``gcs-utm run SCENARIO --external --fly`` on a real PX4 fixed wing (SIH plane, airframe
10041) beside a PX4 quadrotor (issue 18: use case 1's vehicle pair on real PX4).

The SIH plane of PX4 v1.15.2 needs its actuator setup corrected before it can fly at all
(``PX4_SIH_PLANE_PARAMS``, set over MAVLink as a ground station's parameter editor does); the
run then uploads each filed plan, arms, takes off (the plane: a runway take-off in AUTO.TAKEOFF,
then a loiter at the first waypoint's altitude) and starts the mission at the first waypoint's
time. Checked on the report's tracks: the plane waits for its mission near its first waypoint
(NAV_TAKEOFF carries that position), each vehicle passes every waypoint of its plan, and the
report says uploaded, verified, armed and started for both.
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

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, PX4_SIH_PLANE_PARAMS, SitlProcess
from tests.autopilot.pilot import PilotLink, Sample, local_m, offset_deg

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; run --speed matches it
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
START_S = 120.0  # first waypoint time: take-off, climb and a slow upload (80 s) fit before
# (sys_id, vehicle, home east/north m, cruise m/s, waypoints east/north/alt AGL m); the plane's
# operational volume (100 m) holds the loiter it waits in at its first waypoint
PLANS = {
    "PLANE": (1, "fixed_wing", (0.0, 0.0), 14.0,
              [(0.0, 450.0, 60.0), (-700.0, 450.0, 60.0), (-700.0, -250.0, 60.0)]),
    "QUAD": (2, "multirotor", (-300.0, 150.0), 8.0,
             [(-300.0, 150.0, 25.0), (-300.0, -150.0, 25.0)]),
}  # fmt: skip
PLANE_TOLERANCE_M = 40.0  # horizontal: a fixed wing turns before its waypoint (NPFG)
QUAD_TOLERANCE_M = 12.0
PLANE_WAIT_M = 150.0  # its loiter radius (NAV_LOITER_RAD 80 m) and margin (was 350 m)
ALTITUDE_TOLERANCE_M = 10.0


def _scenario(path: Path) -> Path:
    ops = []
    for uas, (sys_id, kind, home, cruise, wps) in PLANS.items():
        points = ", ".join(f"{{ east_m = {e}, north_m = {n}, alt_agl_m = {a} }}" for e, n, a in wps)
        ops.append(
            f"""
[[operations]]
id = "{uas}"
sys_id = {sys_id}
priority = {sys_id}
vehicle = "{kind}"
autopilot = "px4"
icao24 = "c0ffe{sys_id}"
conops = "inspection"
operator = "pilot-{uas.lower()}"
cruise_speed_mps = {cruise}
flight_geometry_m = {20.0 if kind == "fixed_wing" else 5.0}
operational_volume_m = {100.0 if kind == "fixed_wing" else 10.0}
endurance_s = 1200.0
max_climb_rate_mps = {4.0 if kind == "fixed_wing" else 2.0}
start_s = {START_S}
home = {{ east_m = {home[0]}, north_m = {home[1]}, alt_agl_m = 0.0 }}
waypoints = [{points}]
"""
        )
    path.write_text(
        f"""
[scenario]
name = "fly_plane"
description = "a PX4 SIH plane and a PX4 quad fly their filed plans (--external --fly)"
duration_s = 250.0

[airspace]
origin_lat_deg = {LAT0}
origin_lon_deg = {LON0}
ground_elevation_amsl_m = {GROUND_M}
"""
        + "".join(ops)
    )
    return path


def _closest_m(samples: list[Sample], east_m: float, north_m: float, alt_amsl_m: float) -> float:
    """Horizontal distance of the closest pass within the altitude tolerance."""
    best = math.inf
    for s in samples:
        e, n = local_m(LAT0, LON0, s.lat_deg, s.lon_deg)
        if abs(s.alt_amsl_m - alt_amsl_m) < ALTITUDE_TOLERANCE_M:
            best = min(best, math.hypot(e - east_m, n - north_m))
    return best


@pytest.mark.timeout(300)
def test_px4_plane_and_quad_fly_their_plans(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    for _uas, (sys_id, kind, home, _cruise, _wps) in PLANS.items():
        lat, lon = offset_deg(LAT0, LON0, *home)
        airframe = "plane" if kind == "fixed_wing" else "quad"
        px4(instance=sys_id - 1, airframe=airframe, home=(lat, lon), speed=SPEED)
    pilot = PilotLink(PLANS["PLANE"][0] - 1)
    try:  # closed before the run: parsing PX4's onboard stream costs CPU the run needs
        pilot.wait_ready(90.0)
        pilot.set_params(PX4_SIH_PLANE_PARAMS)
    finally:
        pilot.close()
    _run_and_check(tmp_path)


def _run_and_check(tmp_path: Path) -> None:
    scenario = _scenario(tmp_path / "fly_plane.toml")
    out_dir = tmp_path / "runs"
    t0 = time.monotonic()
    run = subprocess.run(
        [sys.executable, "-m", "gcs_utm", "run", str(scenario), "--external", "--fly",
         "--auto-accept", "--headless", "--no-figures", "--speed", str(SPEED),
         "--out", str(out_dir)],
        capture_output=True, text=True, timeout=240, stdin=subprocess.DEVNULL, check=False,
    )  # fmt: skip
    log = (run.stdout + run.stderr)[-6000:]
    print(f"run: {time.monotonic() - t0:.0f} s wall")
    assert run.returncode == 0, log
    report = json.loads((out_dir / "fly_plane.json").read_text())
    fly = {f["uas"]: f for f in report["fly"]}
    threats = [(t["kind"], t["uas"], t["detected_at_s"]) for t in report["threats"]]
    print(f"threats: {threats}")
    for uas in PLANS:
        f = fly[uas]
        assert not f["error"], f"{uas}: {f}\n{log}"
        assert f["uploaded"] and f["verified"] and f["armed"] and f["started"], f"{f}\n{log}"
    tracks = [[Sample(*p) for p in t] for t in report["tracks"].values()]
    # the plane waited for its mission near its first waypoint (it took off to that point),
    # not where its climb ended: its mission reaches that waypoint on time
    e0, n0, a0 = PLANS["PLANE"][4][0]
    wait_m = min(_distance_at_m(t, START_S, e0, n0, GROUND_M + a0) for t in tracks)
    print(f"PLANE: {wait_m:.0f} m from its first waypoint at its time")
    assert wait_m < PLANE_WAIT_M
    for uas, (_sys_id, kind, _home, _cruise, wps) in PLANS.items():
        tolerance = PLANE_TOLERANCE_M if kind == "fixed_wing" else QUAD_TOLERANCE_M
        for e, n, a in wps:
            miss = min(_closest_m(t, e, n, GROUND_M + a) for t in tracks)
            print(f"{uas}: waypoint ({e}, {n}, {a} AGL) passed at {miss:.1f} m")
            assert miss < tolerance, f"{uas}: ({e}, {n}, {a}) missed by {miss:.1f} m\n{fly[uas]}"


def _distance_at_m(
    track: list[Sample], t_s: float, east_m: float, north_m: float, alt_amsl_m: float
) -> float:
    """Horizontal distance at ``t_s`` (the nearest sample within 2 s and the altitude
    tolerance; inf when there is none)."""
    near = [s for s in track if abs(s.t_s - t_s) < 2.0]
    if not near:
        return math.inf
    s = min(near, key=lambda smp: abs(smp.t_s - t_s))
    if abs(s.alt_amsl_m - alt_amsl_m) >= ALTITUDE_TOLERANCE_M:
        return math.inf
    e, n = local_m(LAT0, LON0, s.lat_deg, s.lon_deg)
    return math.hypot(e - east_m, n - north_m)
