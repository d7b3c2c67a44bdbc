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

import math
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, PX4_SIH_PLANE_PARAMS, SitlProcess
from tests.autopilot.fly import FlyOp, closest_pass_m, run_fly, write_scenario
from tests.autopilot.pilot import PilotLink, Sample, local_m, offset_deg

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; run --speed matches it
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
START_S = 120.0  # first waypoint time: take-off, climb and a slow upload (80 s) fit before
# the plane's operational volume (100 m) holds the loiter it waits in at its first waypoint
PLANE = FlyOp("PLANE", 1, "fixed_wing", "px4", (0.0, 0.0),
              [(0.0, 450.0, 60.0), (-700.0, 450.0, 60.0), (-700.0, -250.0, 60.0)],
              14.0, START_S, conops="inspection")  # fmt: skip
QUAD = FlyOp("QUAD", 2, "multirotor", "px4", (-300.0, 150.0),
             [(-300.0, 150.0, 25.0), (-300.0, -150.0, 25.0)], 8.0, START_S,
             conops="inspection")  # fmt: skip
PLANE_TOLERANCE_M = 40.0  # horizontal: a fixed wing turns before its waypoint (NPFG)
QUAD_TOLERANCE_M = 12.0
PLANE_WAIT_M = 150.0  # its loiter radius (NAV_LOITER_RAD 80 m) and margin
ALTITUDE_TOLERANCE_M = 10.0


@pytest.mark.timeout(300)
def test_px4_plane_and_quad_fly_their_plans(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    for op in (PLANE, QUAD):
        lat, lon = offset_deg(LAT0, LON0, *op.home_m)
        airframe = "plane" if op.fixed_wing else "quad"
        px4(instance=op.sys_id - 1, airframe=airframe, home=(lat, lon), speed=SPEED)
    pilot = PilotLink(PLANE.sys_id - 1)
    try:  # closed before the run: parsing PX4's onboard stream costs CPU the run needs
        pilot.wait_ready(90.0)
        pilot.set_params(PX4_SIH_PLANE_PARAMS)
    finally:
        pilot.close()
    scenario = write_scenario(
        tmp_path / "fly_plane.toml",
        "a PX4 SIH plane and a PX4 quad fly their filed plans (--external --fly)",
        (LAT0, LON0, GROUND_M),
        250.0,
        (PLANE, QUAD),
    )
    report, _log = run_fly(scenario, tmp_path / "runs", SPEED, timeout_s=240.0)
    tracks = [[Sample(*p) for p in t] for t in report["tracks"].values()]
    # the plane waited for its mission near its first waypoint (it took off to that point),
    # not where its climb ended: its mission reaches that waypoint on time
    e0, n0, a0 = PLANE.waypoints[0]
    wait_m = min(_distance_at_m(t, START_S, e0, n0, GROUND_M + a0) for t in tracks)
    print(f"PLANE: {wait_m:.0f} m from its first waypoint at its time")
    assert wait_m < PLANE_WAIT_M
    points = [(*local_m(LAT0, LON0, s.lat_deg, s.lon_deg), s.alt_amsl_m) for t in tracks for s in t]
    for op in (PLANE, QUAD):
        tolerance = PLANE_TOLERANCE_M if op.fixed_wing else QUAD_TOLERANCE_M
        for e, n, a in op.waypoints:
            miss = closest_pass_m(points, e, n, GROUND_M + a, ALTITUDE_TOLERANCE_M)
            print(f"{op.uas}: waypoint ({e}, {n}, {a} AGL) passed at {miss:.1f} m")
            assert miss < tolerance, f"{op.uas}: ({e}, {n}, {a}) missed by {miss:.1f} m"


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
