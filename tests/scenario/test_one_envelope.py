"""One envelope per vehicle: the simulated vehicle of a scenario run flies within the speeds
the UTM plans with (gcs_utm.envelope), and a filed fixed-wing plan slower than the vehicle's
minimum airspeed is refused at filing, naming the operation, the leg and the speeds."""

from __future__ import annotations

from pathlib import Path

import pytest

from gcs_utm.app import vehicle_specs
from gcs_utm.flyable import leg_speeds_mps, plan_speed_problem
from gcs_utm.scenario import ScenarioError, load_any

_SCENARIO = """
[scenario]
name = "envelopes"
description = ""
duration_s = 200.0
[airspace]
origin_lat_deg = 40.0
origin_lon_deg = -3.0
ground_elevation_amsl_m = 600.0
[[operations]]
id = "PLANE"
sys_id = 1
priority = 1
vehicle = "fixed_wing"
cruise_speed_mps = {cruise}
flight_geometry_m = 10.0
operational_volume_m = 20.0
max_climb_rate_mps = 5.0
waypoints = [
    {{ east_m = 0.0, north_m = 0.0, alt_agl_m = 80.0, t_s = 0.0 }},
    {{ east_m = 1370.0, north_m = 0.0, alt_agl_m = 80.0, t_s = 100.0 }},
    {{ east_m = 1370.0, north_m = {north}, alt_agl_m = 80.0, t_s = 200.0 }},
]
[[operations]]
id = "QUAD"
sys_id = 2
priority = 1
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
waypoints = [
    {{ east_m = 0.0, north_m = 500.0, alt_agl_m = 50.0, t_s = 0.0 }},
    {{ east_m = 0.0, north_m = 500.0, alt_agl_m = 50.0, t_s = 100.0 }},
]
"""


def _write(tmp_path: Path, cruise: float, north: float) -> Path:
    path = tmp_path / "envelopes.toml"
    path.write_text(_SCENARIO.format(cruise=cruise, north=north))
    return path


def test_the_simulated_vehicles_fly_the_utms_envelope(tmp_path: Path) -> None:
    """The issue's plane: cruise 13.7 m/s, the UTM's minimum 0.7 x 13.7 = 9.59 m/s; the
    simulated plane's default minimum airspeed (12 m/s) was above it."""
    scenario = load_any(_write(tmp_path, 13.7, 1370.0), t0_s=0.0)
    specs = {s.sys_id: s for s in vehicle_specs(scenario, lead_s=5.0)}
    for op in scenario.operations:
        env = op.performance()
        lim = specs[op.sys_id].limits()
        assert lim.min_airspeed_mps == pytest.approx(env.min_speed_mps), op.id
        assert lim.max_speed_mps == pytest.approx(env.max_speed_mps), op.id
    plane = scenario.operations[0]
    assert plane.performance().min_speed_mps == pytest.approx(9.59)
    assert min(leg_speeds_mps(plane)) >= plane.performance().min_speed_mps


def test_a_plan_slower_than_a_fixed_wings_minimum_airspeed_is_refused(tmp_path: Path) -> None:
    # leg 2: 800 m in 100 s = 8 m/s, below 0.7 x 13.7 = 9.59 m/s
    with pytest.raises(ScenarioError) as err:
        load_any(_write(tmp_path, 13.7, 800.0), t0_s=0.0)
    text = str(err.value)
    assert "operations[0] (PLANE): waypoints: operation PLANE: leg 2 (waypoint 2 to 3)" in text
    assert "planned at 8.0" in text  # 8 m/s to the local sphere's 0.1 %
    assert "m/s, below the fixed wing's minimum airspeed 9.59 m/s" in text


def test_a_hovering_multirotor_plan_is_flyable(tmp_path: Path) -> None:
    scenario = load_any(_write(tmp_path, 13.7, 1370.0), t0_s=0.0)
    quad = scenario.operations[1]
    assert leg_speeds_mps(quad) == [0.0]
    assert plan_speed_problem(quad) is None
