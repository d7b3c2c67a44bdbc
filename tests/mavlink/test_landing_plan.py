"""A plan that lands (return home, a landing site) is uploaded as a landing: a multirotor's
mission ends with a NAV_LAND at the touchdown point, not a waypoint at ground level (PX4 and
ArduCopter hover over such a waypoint, armed, and its threat never closes); everything
before it stays where the plan has it, above the floor over home."""

from __future__ import annotations

import math
from typing import Any

import pytest

from adapters.mavlink import plan_to_mission_items
from adapters.mavlink.mission import (
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_WAYPOINT,
    is_nav,
    same_item,
    stored_form,
)
from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.geo import haversine_m
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    Maneuver,
    OperationId,
    SysId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
)

HOME_ENZ = (-300.0, 80.0, 0.0)


def _return_home() -> FlightPlan:
    """TD's return_home for a multirotor jammed at 60 m on an eastbound leg."""
    op = sc.make_operation("A", [(0.0, 0.0, 60.0), (1000.0, 0.0, 60.0)], home_enz=HOME_ENZ)
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MonitoringConfig())
    alts = td.resolve_single(
        sc.threat(ThreatKind.JAMMING_ATTACK, ["A"]),
        OperationId("A"),
        sc.snapshot([op]),
        maneuvers={Maneuver.RETURN_HOME},
    )
    [alt] = alts
    assert alt.plan is not None
    return alt.plan


@pytest.mark.parametrize("autopilot", [Autopilot.PX4, Autopilot.ARDUPILOT])
def test_a_multirotors_return_home_ends_with_a_landing_at_home(autopilot: Autopilot) -> None:
    plan = _return_home()
    home_lat, home_lon = sc.FRAME.point_to_wgs84(HOME_ENZ[0], HOME_ENZ[1])
    floor_m = HOME_ENZ[2] + DeconflictionConfig().min_height_above_home_m
    # the plan: cruise to above home, then down onto it (the landing)
    last, above = plan.waypoints[-1], plan.waypoints[-2]
    assert haversine_m(last.lat_deg, last.lon_deg, home_lat, home_lon) < 1.0
    assert math.isclose(last.alt_amsl_m, HOME_ENZ[2], abs_tol=0.1)
    assert haversine_m(above.lat_deg, above.lon_deg, home_lat, home_lon) < 1.0
    assert all(w.alt_amsl_m >= floor_m for w in plan.waypoints[:-1])
    items = plan_to_mission_items(plan, autopilot, kind=VehicleKind.MULTIROTOR, lands=True)
    nav = [it for it in items if is_nav(it.command)]
    land = nav[-1]
    assert land.command == MAV_CMD_NAV_LAND and land is items[-1]
    assert haversine_m(land.lat_deg, land.lon_deg, home_lat, home_lon) < 1.0
    assert all(it.command == MAV_CMD_NAV_WAYPOINT for it in nav[:-1])
    assert all(it.z >= floor_m for it in nav[:-1]), [it.z for it in nav]  # above the floor
    # what the autopilot keeps of it reads back as the same mission
    assert all(same_item(it, stored_form(it, autopilot), autopilot) == "" for it in items)
    # without ``lands`` (a plan that only passes low): its waypoints, no landing
    plain = plan_to_mission_items(plan, autopilot, kind=VehicleKind.MULTIROTOR)
    assert all(it.command != MAV_CMD_NAV_LAND for it in plain)


def test_a_fixed_wings_landing_plan_gets_no_nav_land() -> None:
    """A fixed wing's return_home ends above home, where it circles until its own landing
    sequence is flown: ``lands`` adds no NAV_LAND (PX4 refuses one after a plain leg)."""
    lat, lon = sc.FRAME.point_to_wgs84(0.0, 0.0)
    plan = FlightPlan(
        operation_id=OperationId("P"),
        version=2,
        waypoints=(
            Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=80.0, t_s=0.0),
            Waypoint4D(lat_deg=lat + 0.005, lon_deg=lon, alt_amsl_m=80.0, t_s=30.0),
        ),
    )
    items = plan_to_mission_items(
        plan, Autopilot.PX4, kind=VehicleKind.FIXED_WING, min_speed_mps=12.0, lands=True
    )
    assert all(it.command != MAV_CMD_NAV_LAND for it in items)


async def test_a_second_return_home_is_not_sent_back_to_the_first_ones_approach(
    env: Any,
) -> None:
    """Through the hub: a return home uploaded while the vehicle already descends on an
    earlier one (EM re-plans while the threat is open) ends with its own NAV_LAND; the
    earlier NAV_LAND and the waypoint above home before it, read back into the vehicle's
    mission, are not a pilot's landing sequence to rejoin (the vehicle climbed back to that
    waypoint's height before landing)."""
    v = await env.vehicle(8)
    plan = _return_home()
    cruise_m = plan.waypoints[-2].alt_amsl_m
    res = await env.hub.upload_plan(SysId(8), plan, lands=True)
    assert res.ok and res.verified, res
    assert v.mission[-1].command == MAV_CMD_NAV_LAND
    # 20 m lower over home, on the way down: the next return home starts there
    low = cruise_m - 20.0
    last = plan.waypoints[-1]
    t = plan.waypoints[-2].t_s + 10.0
    again = FlightPlan(
        operation_id=plan.operation_id,
        version=plan.version + 1,
        waypoints=(
            Waypoint4D(lat_deg=last.lat_deg, lon_deg=last.lon_deg, alt_amsl_m=low, t_s=t),
            Waypoint4D(
                lat_deg=last.lat_deg, lon_deg=last.lon_deg, alt_amsl_m=last.alt_amsl_m, t_s=t + 20
            ),
        ),
    )
    res = await env.hub.upload_plan(SysId(8), again, lands=True)
    assert res.ok and res.verified, res
    got = [(m.command, round(m.z, 2)) for m in v.mission if is_nav(m.command)]
    assert got == [(MAV_CMD_NAV_WAYPOINT, round(low, 2)), (MAV_CMD_NAV_LAND, last.alt_amsl_m)]
    v.close()
