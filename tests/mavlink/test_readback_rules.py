"""Mission encoding and readback by meaning: the frames and stored defaults of each autopilot
(measured on PX4 v1.15.2 and ArduPilot 4.6 SITL; see docs/autopilots.md)."""

from __future__ import annotations

import math
from dataclasses import replace

from adapters.mavlink.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_FRAME_MISSION,
    MissionItem,
    plan_to_mission_items,
    same_item,
    start_item,
)
from gcs_utm.model import Autopilot, FlightPlan, OperationId, VehicleKind, Waypoint4D


def _plan() -> FlightPlan:
    wps = tuple(
        Waypoint4D(lat_deg=47.3977 + 0.0005 * i, lon_deg=8.5456, alt_amsl_m=500.0, t_s=10.0 * i)
        for i in range(3)
    )
    return FlightPlan(operation_id=OperationId("op"), version=1, waypoints=wps)


WP = MissionItem(seq=1, command=16, param1=2.4, param4=math.nan, x=473977000, y=85456000, z=500.0)
SPEED = MissionItem(seq=2, command=178, frame=2, param1=1.0, param2=5.0, param3=-1.0)


def test_speed_items_go_in_the_mission_frame() -> None:
    items = plan_to_mission_items(_plan())
    speeds = [it for it in items if it.command == MAV_CMD_DO_CHANGE_SPEED]
    assert speeds and all(it.frame == MAV_FRAME_MISSION for it in speeds)
    assert all(it.frame == 0 for it in items if it.command == 16)


def test_px4_reads_back_int_frames_and_keeps_nan() -> None:
    assert same_item(WP, replace(WP, frame=5), Autopilot.PX4) == ""
    assert same_item(replace(WP, frame=3), replace(WP, frame=6), Autopilot.PX4) == ""
    assert "frame" in same_item(WP, replace(WP, frame=6), Autopilot.PX4)
    assert "param4" in same_item(WP, replace(WP, param4=0.0), Autopilot.PX4)
    assert same_item(SPEED, SPEED, Autopilot.PX4) == ""


def test_ardupilot_stores_nan_as_zero_and_do_items_in_frame_0() -> None:
    copter = replace(WP, param1=2.0, param4=0.0)  # hold kept in whole seconds, yaw 0
    assert same_item(WP, copter, Autopilot.ARDUPILOT, VehicleKind.MULTIROTOR) == ""
    plane = replace(WP, param1=0.0, param4=0.0)  # ArduPlane keeps no hold time
    assert same_item(WP, plane, Autopilot.ARDUPILOT, VehicleKind.FIXED_WING) == ""
    assert same_item(SPEED, replace(SPEED, frame=0), Autopilot.ARDUPILOT) == ""
    assert "param4" in same_item(WP, replace(copter, param4=90.0), Autopilot.ARDUPILOT)


def test_positions_to_1e7_deg_and_altitude_to_1_cm() -> None:
    assert same_item(WP, replace(WP, frame=5, x=WP.x + 1), Autopilot.PX4) == ""
    assert "x" in same_item(WP, replace(WP, frame=5, x=WP.x + 2), Autopilot.PX4)
    assert same_item(WP, replace(WP, frame=5, z=500.009), Autopilot.PX4) == ""
    assert "z" in same_item(WP, replace(WP, frame=5, z=500.02), Autopilot.PX4)
    assert "command" in same_item(WP, replace(WP, frame=5, command=17), Autopilot.PX4)


def test_ardupilot_starts_at_the_navigation_item() -> None:
    items = plan_to_mission_items(_plan(), Autopilot.ARDUPILOT, start_index=1)
    flagged = next(it for it in items if it.current)
    assert flagged.command == MAV_CMD_DO_CHANGE_SPEED
    seq, skipped = start_item(items, Autopilot.ARDUPILOT)
    assert items[seq].command == 16 and seq == flagged.seq + 1 and skipped == flagged
    assert start_item(items, Autopilot.PX4) == (flagged.seq, None)
    # ArduCopter keeps whole seconds of hold: they are sent whole
    assert all(it.param1 == round(it.param1) for it in items if it.command == 16)
