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

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.fly import FlyOp, closest_pass_m, run_fly, write_scenario
from tests.autopilot.pilot import PilotLink, local_m, offset_deg

SPEED = 5.0  # ArduPilot --speedup; run --speed matches it
LAT0, LON0, GROUND_M, _HEADING = ARDUPILOT_DEFAULT_HOME
START_S = 75.0  # first waypoint time: arming is refused ~20-30 s (sim) after boot


def _copter(
    uas: str, sys_id: int, home_m: tuple[float, float], wps: list[tuple[float, float, float]]
) -> FlyOp:
    return FlyOp(uas, sys_id, "multirotor", "ardupilot", home_m, wps, 6.0, START_S)


# two copters well apart
COPTERS = [
    _copter("COPTER1", 1, (0.0, 0.0), [(0.0, 0.0, 20.0), (120.0, 0.0, 20.0), (120.0, 90.0, 20.0)]),
    _copter("COPTER2", 2, (0.0, -200.0), [(0.0, -200.0, 30.0), (-120.0, -200.0, 30.0)]),
]
# one ArduPlane: north from its runway, then west; its volume holds its waiting loiter
PLANE = FlyOp(
    "PLANE", 1, "fixed_wing", "ardupilot", (0.0, 0.0),
    [(0.0, 500.0, 60.0), (-800.0, 500.0, 60.0), (-800.0, -300.0, 60.0)],
    22.0, START_S, operational_volume_m=120.0,
)  # fmt: skip
PLANE_TOLERANCE_M = 40.0
WAYPOINT_TOLERANCE_M = 8.0  # horizontal (WPNAV_RADIUS 2 m, samples at 10 Hz)
ALTITUDE_TOLERANCE_M = 3.0


@pytest.mark.timeout(240)
def test_two_ardupilot_copters_fly_their_plans(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    _fly(ardupilot, tmp_path, COPTERS, "copter")


@pytest.mark.timeout(240)
def test_ardupilot_plane_flies_its_plan(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    _fly(ardupilot, tmp_path, [PLANE], "plane")


def _fly(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path, ops: list[FlyOp], vehicle: str
) -> None:
    pilots = {}
    for op in ops:
        lat, lon = offset_deg(LAT0, LON0, *op.home_m)
        i = op.sys_id - 1
        ardupilot(
            instance=i,
            vehicle=vehicle,
            home=(lat, lon, GROUND_M, 0.0),
            speed=SPEED,
            extra_args=("--serial0", "udpclient:127.0.0.1:14550"),
        )
        wait_tcp_listening(5762 + 10 * i)
        pilots[op.uas] = PilotLink(i, autopilot="ardupilot", tcp_port=5762 + 10 * i)
    try:
        for pilot in pilots.values():
            pilot.wait_ready()  # streaming positions before the run starts
        scenario = write_scenario(
            tmp_path / "fly_ardupilot.toml",
            f"ArduPilot {vehicle}s fly their filed plans (--external --fly)",
            (LAT0, LON0, GROUND_M),
            160.0,
            ops,
        )

        def read_positions() -> None:
            for pilot in pilots.values():
                pilot.poll(0.02)

        run_fly(scenario, tmp_path / "runs", SPEED, timeout_s=200.0, while_running=read_positions)
        _check_waypoints(pilots, ops)
    finally:
        for pilot in pilots.values():
            pilot.close()


def _check_waypoints(pilots: dict[str, PilotLink], ops: list[FlyOp]) -> None:
    """ArduPilot's own positions pass every waypoint of each plan."""
    missed = []
    for op in ops:
        samples = pilots[op.uas].samples
        assert samples, f"{op.uas}: no positions from ArduPilot on SERIAL1"
        top_m = max(s.alt_amsl_m for s in samples) - GROUND_M
        print(f"{op.uas}: {len(samples)} positions, highest {top_m:.1f} m above ground")
        points = [(*local_m(LAT0, LON0, s.lat_deg, s.lon_deg), s.alt_amsl_m) for s in samples]
        tolerance = PLANE_TOLERANCE_M if op.fixed_wing else WAYPOINT_TOLERANCE_M
        alt_tol_m = 10.0 if op.fixed_wing else ALTITUDE_TOLERANCE_M
        for e, n, a in op.waypoints:
            miss = closest_pass_m(points, e, n, GROUND_M + a, alt_tol_m)
            print(f"{op.uas}: waypoint ({e}, {n}, {a} AGL) passed at {miss:.1f} m")
            if miss >= tolerance:
                missed.append(f"{op.uas}: ({e}, {n}, {a}) missed by {miss:.1f} m")
    assert not missed, missed
