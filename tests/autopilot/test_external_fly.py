"""``gcs-utm run SCENARIO --external --fly`` on two real PX4 quadrotors (issue 18 item 9).

Each PX4 starts on the ground at its operation's home (the first waypoint's position); the
run uploads each filed plan (verified by readback), arms, takes off and switches to mission
mode at the plan's first waypoint time. The report's tracks must pass every waypoint of each
plan, and the run must report each mission as uploaded, verified and started.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.pilot import local_m, offset_deg

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; run --speed matches it
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
# (sys_id, home east/north m, waypoints east/north/alt AGL m): two quads well apart, so the
# UTM has no conflict to resolve and each vehicle flies the plan as filed
PLANS = {
    "UAS1": (1, (0.0, 0.0), [(0.0, 0.0, 25.0), (160.0, 0.0, 25.0), (160.0, 120.0, 25.0)]),
    "UAS2": (2, (0.0, -300.0), [(0.0, -300.0, 35.0), (-160.0, -300.0, 35.0)]),
}
WAYPOINT_TOLERANCE_M = 12.0  # horizontal; PX4's acceptance radius and 0.5 s track samples
ALTITUDE_TOLERANCE_M = 5.0


def _scenario(path: Path) -> Path:
    ops = []
    for uas, (sys_id, home, wps) in PLANS.items():
        points = ", ".join(f"{{ east_m = {e}, north_m = {n}, alt_agl_m = {a} }}" for e, n, a in wps)
        ops.append(
            f"""
[[operations]]
id = "{uas}"
sys_id = {sys_id}
priority = {sys_id}
vehicle = "multirotor"
autopilot = "px4"
icao24 = "c0ffe{sys_id}"
conops = "survey"
operator = "pilot-{uas.lower()}"
cruise_speed_mps = 8.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
endurance_s = 1200.0
max_climb_rate_mps = 2.0
start_s = 60.0
home = {{ east_m = {home[0]}, north_m = {home[1]}, alt_agl_m = 0.0 }}
waypoints = [{points}]
"""
        )
    path.write_text(
        f"""
[scenario]
name = "fly_px4"
description = "two PX4 quads fly their filed plans (--external --fly)"
duration_s = 130.0

[airspace]
origin_lat_deg = {LAT0}
origin_lon_deg = {LON0}
ground_elevation_amsl_m = {GROUND_M}
"""
        + "".join(ops)
    )
    return path


def _passes(track: list[list[float]], east_m: float, north_m: float, alt_amsl_m: float) -> bool:
    for _t, lat, lon, alt in track:
        e, n = local_m(LAT0, LON0, lat, lon)
        if (
            math.hypot(e - east_m, n - north_m) < WAYPOINT_TOLERANCE_M
            and abs(alt - alt_amsl_m) < ALTITUDE_TOLERANCE_M
        ):
            return True
    return False


@pytest.mark.timeout(240)
def test_two_px4_quads_fly_their_plans(px4: Callable[..., SitlProcess], tmp_path: Path) -> None:
    for sys_id, home, _wps in PLANS.values():
        lat, lon = offset_deg(LAT0, LON0, *home)
        px4(instance=sys_id - 1, airframe="quad", home=(lat, lon), speed=SPEED)
    scenario = _scenario(tmp_path / "fly_px4.toml")
    out_dir = tmp_path / "runs"
    run = subprocess.run(
        [sys.executable, "-m", "gcs_utm", "run", str(scenario), "--external", "--fly",
         "--auto-accept", "--headless", "--no-figures", "--speed", str(SPEED),
         "--out", str(out_dir)],
        capture_output=True, text=True, timeout=200, stdin=subprocess.DEVNULL, check=False,
    )  # fmt: skip
    log = (run.stdout + run.stderr)[-5000:]
    assert run.returncode == 0, log
    report = json.loads((out_dir / "fly_px4.json").read_text())
    fly = {f["uas"]: f for f in report["fly"]}
    for uas in PLANS:
        f = fly[uas]
        assert not f["error"], f"{uas}: {f}\n{log}"
        assert f["uploaded"] and f["verified"] and f["armed"] and f["started"], f"{f}\n{log}"
    tracks = list(report["tracks"].values())
    for uas, (_sys_id, _home, wps) in PLANS.items():
        for e, n, a in wps:
            assert any(_passes(t, e, n, GROUND_M + a) for t in tracks), (
                f"{uas}: no track passes waypoint ({e}, {n}, {a} AGL)\n{fly[uas]}\n{log}"
            )
