"""``run --external --fly`` uploads each operation's plan version current at upload time, not
the filed one: a resolution accepted before the take-off must be what the vehicle flies.

The external vehicle is a built-in PX4-like ``sitl`` vehicle on the ground, reached over the
run's ``--link``, so the run takes the same path as with a real autopilot (discovery, home,
upload with readback). Before the upload the operation's plan is replaced by a version 2 moved
100 m north, as an accepted recommendation replaces it; the vehicle's mission must be that
version.
"""

from __future__ import annotations

import dataclasses
import json
import socket
from pathlib import Path

from gcs_utm.app import OperatorMode, RunOptions, Runtime, run_scenario
from gcs_utm.model import OperationId
from gcs_utm.settings import Settings
from sitl import Fleet, SimTime, VehicleSpec

SPEED = 8.0
LAT0, LON0, GROUND_M = 45.4671160, -73.7578370, 32.34
NORTH_DEG = 100.0 / 111_132.0  # 100 m of latitude
MAV_CMD_NAV_WAYPOINT = 16

SCENARIO = f"""
[scenario]
name = "fly_current_plan"
description = "the plan version current at upload is flown"
duration_s = 45.0

[airspace]
origin_lat_deg = {LAT0}
origin_lon_deg = {LON0}
ground_elevation_amsl_m = {GROUND_M}

[[operations]]
id = "UAS1"
sys_id = 1
priority = 1
vehicle = "multirotor"
autopilot = "px4"
icao24 = "c0ffe1"
conops = "survey"
operator = "pilot-uas1"
cruise_speed_mps = 8.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
endurance_s = 1200.0
max_climb_rate_mps = 2.0
start_s = 60.0
home = {{ east_m = 0.0, north_m = 0.0, alt_agl_m = 0.0 }}
waypoints = [{{ east_m = 0.0, north_m = 0.0, alt_agl_m = 25.0 }},
             {{ east_m = 160.0, north_m = 0.0, alt_agl_m = 25.0 }}]
"""


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


async def test_fly_uploads_the_current_plan_version_not_the_filed_one(tmp_path: Path) -> None:
    path = tmp_path / "fly_current_plan.toml"
    path.write_text(SCENARIO)
    port = _free_udp_port()
    spec = VehicleSpec(
        instance=0,
        sys_id=1,
        home_lat_deg=LAT0,
        home_lon_deg=LON0,
        home_alt_amsl_m=GROUND_M,
        gcs_port=port,
        bind_port=0,
        tcp_port=0,
    )
    moved: list[tuple[float, float]] = []

    async def accept_a_new_version(rt: Runtime) -> None:
        op = rt.airspace.operation(OperationId("UAS1"))
        wps = tuple(
            dataclasses.replace(w, lat_deg=w.lat_deg + NORTH_DEG) for w in op.plan.waypoints
        )
        rt.airspace.replace_plan(
            dataclasses.replace(
                op.plan, version=op.plan.version + 1, waypoints=wps, reason="go_left"
            )
        )
        moved.extend((w.lat_deg, w.lon_deg) for w in wps)

    options = RunOptions(
        speed=SPEED,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        external=True,
        fly=True,
        link=f"udpin:127.0.0.1:{port}",
        out_dir=tmp_path / "runs",
        figures=False,
        lead_s=0.0,
    )
    async with Fleet([spec], SimTime(SPEED)) as fleet:
        await run_scenario(path, Settings(), options, on_runtime=accept_a_new_version)
        items = fleet.vehicle(1).mission_items()
    report = json.loads((tmp_path / "runs" / "fly_current_plan.json").read_text())
    fly = report["fly"][0]
    assert fly["uploaded"] and fly["verified"], fly
    assert any("plan v2 uploaded" in s for s in fly["steps"]), fly
    flown = [(it.x / 1e7, it.y / 1e7) for it in items if it.command == MAV_CMD_NAV_WAYPOINT]
    assert len(flown) == len(moved), items
    for (lat, lon), (want_lat, want_lon) in zip(flown, moved, strict=True):
        assert abs(lat - want_lat) < 1e-6 and abs(lon - want_lon) < 1e-6, (flown, moved)
