"""One envelope per vehicle: the simulated vehicle of a scenario run flies within the speeds
and vertical rates the UTM plans with (gcs_utm.envelope), and a filed plan it cannot fly (a
fixed wing slower than its minimum airspeed, any vehicle climbing or descending faster than
its envelope) is refused at filing, from a scenario file or over MQTT, naming the
operation, the leg, the speed or rate and the limit."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from adapters.mqtt.codec import FlightPlanSubmission
from adapters.mqtt.config import MqttConfig
from gcs_utm.app import vehicle_specs
from gcs_utm.clock import ManualClock
from gcs_utm.flyable import leg_speeds_mps, plan_problem, plan_rate_problem, plan_speed_problem
from gcs_utm.model import FlightPlan, OperationId, VehicleKind, Waypoint4D
from gcs_utm.scenario import ScenarioError, load_any
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm

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
    {{ east_m = 1370.0, north_m = {north}, alt_agl_m = {end_alt}, t_s = 200.0 }},
]
[[operations]]
id = "QUAD"
sys_id = 2
priority = 1
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
max_climb_rate_mps = 1.0
waypoints = [
    {{ east_m = 0.0, north_m = 500.0, alt_agl_m = 50.0, t_s = 0.0 }},
    {{ east_m = 0.0, north_m = 500.0, alt_agl_m = 50.0, t_s = 100.0 }},
]
"""


def _write(tmp_path: Path, cruise: float, north: float, end_alt: float = 80.0) -> Path:
    path = tmp_path / "envelopes.toml"
    path.write_text(_SCENARIO.format(cruise=cruise, north=north, end_alt=end_alt))
    return path


def test_the_simulated_vehicles_fly_the_utms_envelope(tmp_path: Path) -> None:
    """The issue's plane: cruise 13.7 m/s, the UTM's minimum 0.7 x 13.7 = 9.59 m/s; the
    simulated plane's default minimum airspeed (12 m/s) was above it. The quad climbs at
    1 m/s: the UTM's envelope descends no faster (the simulated quad's default was 1.5)."""
    scenario = load_any(_write(tmp_path, 13.7, 1370.0), t0_s=0.0)
    specs = {s.sys_id: s for s in vehicle_specs(scenario, lead_s=5.0)}
    for op in scenario.operations:
        env = op.performance()
        lim = specs[op.sys_id].limits()
        assert lim.min_airspeed_mps == pytest.approx(env.min_speed_mps), op.id
        assert lim.max_speed_mps == pytest.approx(env.max_speed_mps), op.id
        assert lim.climb_rate_mps == pytest.approx(env.climb_rate_mps), op.id
        assert lim.descent_rate_mps == pytest.approx(env.descent_rate_mps), op.id
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


@pytest.mark.parametrize(
    ("end_alt", "words"),
    [
        # leg 2: 400 m down in 100 s = 4 m/s, above the fixed wing's 3 m/s descent rate
        (-320.0, "leg 2 (waypoint 2 to 3) descends at 4.00 m/s, faster than its envelope's 3.00"),
        # 600 m up in 100 s = 6 m/s, above its 5 m/s climb rate
        (680.0, "leg 2 (waypoint 2 to 3) climbs at 6.00 m/s, faster than its envelope's 5.00"),
    ],
)
def test_a_plan_steeper_than_the_envelope_is_refused(
    tmp_path: Path, end_alt: float, words: str
) -> None:
    with pytest.raises(ScenarioError) as err:
        load_any(_write(tmp_path, 13.7, 1370.0, end_alt), t0_s=0.0)
    text = str(err.value)
    assert f"operations[0] (PLANE): waypoints: operation PLANE: {words} m/s" in text
    assert "(fixed wing: climb 5.00 m/s, descent 3.00 m/s)" in text


def test_a_plan_at_the_envelopes_descent_rate_is_filed(tmp_path: Path) -> None:
    # 300 m down in 100 s = 3 m/s: the fixed wing's descent rate
    plane = load_any(_write(tmp_path, 13.7, 1370.0, -220.0), t0_s=0.0).operations[0]
    assert plan_problem(plane) is None


def _submission(descent_m: float) -> FlightPlanSubmission:
    """A multirotor (climb 3 m/s, descent 1.5 m/s by default) descending ``descent_m`` in
    its second 10 s leg."""
    wps = (
        Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0, t_s=0.0),
        Waypoint4D(lat_deg=40.0005, lon_deg=-3.0, alt_amsl_m=700.0, t_s=10.0),
        Waypoint4D(lat_deg=40.001, lon_deg=-3.0, alt_amsl_m=700.0 - descent_m, t_s=20.0),
    )
    op = OperationId("steep")
    return FlightPlanSubmission(
        operation_id=op,
        operator="alice",
        plan=FlightPlan(operation_id=op, version=1, waypoints=wps),
        t_s=0.0,
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=6.0,
        flight_geometry_m=5.0,
        operational_volume_m=15.0,
    )


async def test_mqtt_filing_refuses_a_descent_faster_than_the_envelope() -> None:
    usm = Usm(Airspace(), ManualClock(0.0))
    gateway = MqttGateway(usm, MqttConfig())
    with pytest.raises(ValueError, match=r"leg 2 \(waypoint 2 to 3\) descends at 2.00 m/s, "):
        await gateway.on_flight_plan(_submission(20.0))
    assert OperationId("steep") not in usm.airspace.operations
    await gateway.on_flight_plan(_submission(15.0))  # 1.5 m/s: its descent rate
    assert OperationId("steep") in usm.airspace.operations


def test_a_short_leg_is_rated_over_half_a_second(tmp_path: Path) -> None:
    """A join of two legs 10 ms long with 2 cm of altitude is rounding; 5 m in it is a jump."""
    plane = load_any(_write(tmp_path, 13.7, 1370.0), t0_s=0.0).operations[0]
    a, b, c = plane.plan.waypoints
    for dz_m, refused in ((0.02, False), (5.0, True)):
        joined = dataclasses.replace(b, alt_amsl_m=b.alt_amsl_m + dz_m, t_s=b.t_s + 0.01)
        wps = (a, b, joined, dataclasses.replace(c, alt_amsl_m=c.alt_amsl_m + dz_m))
        op = dataclasses.replace(plane, plan=dataclasses.replace(plane.plan, waypoints=wps))
        assert (plan_rate_problem(op) is not None) is refused, dz_m
        if refused:
            assert "leg 2 (waypoint 2 to 3) climbs at 10.00 m/s" in str(plan_rate_problem(op))
