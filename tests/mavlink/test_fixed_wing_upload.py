"""What a plan uploaded to a fixed wing carries (issue 31.4): airspeeds no lower than its
minimum airspeed, the pilot's landing sequence kept at the end; and one MISSION_SET_CURRENT
per upload (issue 31.6)."""

from __future__ import annotations

import asyncio
from typing import Any

from adapters.mavlink import plan_to_mission_items
from adapters.mavlink.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_DO_LAND_START,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_WAYPOINT,
    SPEED_TYPE_AIRSPEED,
    SPEED_TYPE_GROUND,
    MissionItem,
    landing_sequence,
    with_landing,
)
from gcs_utm.model import Autopilot, FlightPlan, OperationId, SysId, VehicleKind, Waypoint4D


def _plan(speed_mps: float) -> FlightPlan:
    """Three legs of 111 m (0.001 deg of latitude) flown at ``speed_mps``."""
    dt = 111.2 / speed_mps
    wps = tuple(
        Waypoint4D(lat_deg=47.397 + 0.001 * i, lon_deg=8.5456, alt_amsl_m=550.0, t_s=dt * i)
        for i in range(4)
    )
    return FlightPlan(operation_id=OperationId("plane"), version=2, waypoints=wps)


def _speeds(items: list[MissionItem]) -> list[tuple[float, float]]:
    return [(i.param1, i.param2) for i in items if i.command == MAV_CMD_DO_CHANGE_SPEED]


def test_fixed_wing_speeds_are_airspeeds_never_below_the_minimum() -> None:
    """A "set groundspeed 5" for a plane: ArduPlane takes a type-1 speed as a minimum ground
    speed and flies its cruise airspeed regardless, and 5 m/s is below its stall."""
    slow = _plan(5.0)
    plane = plan_to_mission_items(
        slow, Autopilot.ARDUPILOT, kind=VehicleKind.FIXED_WING, min_speed_mps=10.0
    )
    assert _speeds(plane) == [(SPEED_TYPE_AIRSPEED, 10.0)] * 3
    cruise = plan_to_mission_items(
        _plan(14.0), Autopilot.ARDUPILOT, kind=VehicleKind.FIXED_WING, min_speed_mps=10.0
    )
    assert all(abs(s - 14.0) < 0.01 for _, s in _speeds(cruise))  # above it: as planned
    assert all(t == SPEED_TYPE_AIRSPEED for t, _ in _speeds(cruise))
    # a multirotor keeps ground speeds, slow ones included
    quad = plan_to_mission_items(slow, Autopilot.PX4, kind=VehicleKind.MULTIROTOR)
    assert all(t == SPEED_TYPE_GROUND and abs(s - 5.0) < 0.01 for t, s in _speeds(quad))


def _landing() -> list[MissionItem]:
    """A pilot's ArduPlane mission: home, take-off, a waypoint, then DO_LAND_START, the
    approach waypoint and NAV_LAND."""
    return [
        MissionItem(seq=0, command=MAV_CMD_NAV_WAYPOINT, x=473970000, y=85456000, z=500.0),
        MissionItem(seq=1, command=22, z=30.0, frame=3),
        MissionItem(seq=2, command=MAV_CMD_NAV_WAYPOINT, x=473990000, y=85456000, z=550.0),
        MissionItem(seq=3, command=MAV_CMD_DO_LAND_START, x=473980000, y=85456000),
        MissionItem(seq=4, command=MAV_CMD_NAV_WAYPOINT, x=473975000, y=85456000, z=530.0),
        MissionItem(seq=5, command=MAV_CMD_NAV_LAND, x=473970000, y=85456000, z=500.0),
    ]


def test_landing_sequence_is_kept_at_the_end_of_a_new_mission() -> None:
    mission = _landing()
    landing = landing_sequence(mission)
    assert [i.command for i in landing] == [MAV_CMD_DO_LAND_START, 16, MAV_CMD_NAV_LAND]
    new = plan_to_mission_items(_plan(14.0), Autopilot.ARDUPILOT, kind=VehicleKind.FIXED_WING)
    out = with_landing(new, landing)
    assert out[: len(new)] == new
    tail = out[len(new) :]
    assert [i.command for i in tail] == [MAV_CMD_DO_LAND_START, 16, MAV_CMD_NAV_LAND]
    assert [i.seq for i in out] == list(range(len(out)))
    assert not any(i.current for i in tail)
    assert [(i.x, i.y, i.z) for i in tail] == [(i.x, i.y, i.z) for i in landing]
    assert with_landing(out, landing) == out  # a mission with its own landing keeps it
    assert with_landing(new, []) == new


async def test_upload_to_a_vehicle_with_a_landing_sequence_keeps_it(env: Any) -> None:
    """A plan the UTM uploads ends with the landing sequence of the vehicle's mission (as
    downloaded), and again when a later plan replaces that one (read back from the vehicle)."""
    v = await env.vehicle(5)
    assert (await env.hub.upload_items(SysId(5), _landing(), set_mission_mode=False)).ok
    await env.hub.download_mission(SysId(5))
    for version in (2, 3):
        res = await env.hub.upload_plan(SysId(5), _plan(14.0), start_index=1)
        assert res.ok and res.verified, (version, res)
        commands = [m.command for m in v.mission]
        assert commands[-3:] == [MAV_CMD_DO_LAND_START, 16, MAV_CMD_NAV_LAND], commands
        assert commands.count(MAV_CMD_DO_LAND_START) == 1
        assert (v.mission[-1].x, v.mission[-1].z) == (473970000, 500.0)
    v.close()


async def test_mission_set_current_is_sent_once_when_answered(env: Any) -> None:
    """A vehicle that answers MISSION_SET_CURRENT 80 ms later (its MISSION_CURRENT stream)
    gets one request, not one every few milliseconds."""
    v = await env.vehicle(6)
    v.faults.current_delay_s = 0.08  # under the command timeout (0.1 s here)
    res = await env.hub.upload_plan(SysId(6), _plan(14.0), start_index=1)
    assert res.ok and res.current_set, res
    await asyncio.sleep(0.05)
    sent = [m for m in v.received if m.get_type() == "MISSION_SET_CURRENT"]
    assert len(sent) == 1, len(sent)
    v.close()
