"""A fixed wing's take-off run along its own heading (issue 31): after a landing the soak's
ArduPlane stood where it stopped, 12.5 m south-west of its take-off item's position and
heading north-east (its approach), and took off north-east; it was filed climbing out
north (the heading to its next waypoint) towards that position behind it, and opened
UAS_IN_CV / UAS_OUT_OV 3 s into the take-off. ArduPlane ignores a take-off's position
(``do_takeoff``) and holds the course it rolls on: the heading it armed with."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import pytest

from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import Autopilot, Position, SysId
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mission_points import NavPoint
from gcs_utm.services.usm import Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_fixed_wing_plan as t

HOME = Position(lat_deg=45.4671, lon_deg=-73.7963, alt_amsl_m=32.4)
M_LAT = 110_540.0
M_LON = 111_320.0 * math.cos(math.radians(HOME.lat_deg))


def _pt(seq: int, cmd: int, east: float, north: float, agl: float, amount: float = 0.0) -> NavPoint:
    return NavPoint(
        seq, HOME.lat_deg + north / M_LAT, HOME.lon_deg + east / M_LON,
        HOME.alt_amsl_m + agl, 22.0, True, cmd, 0.0, amount,
    )  # fmt: skip


def _en(p: NavPoint) -> tuple[float, float]:
    return (p.lon_deg - HOME.lon_deg) * M_LON, (p.lat_deg - HOME.lat_deg) * M_LAT


def _flown(heading_deg: float | None, heads_for_position: bool) -> list[NavPoint]:
    # the vehicle stands at home (-8.8, -8.8 from the take-off item's position)
    start = _pt(0, 16, 0.0, 0.0, 0.0)
    takeoff = _pt(1, 22, 8.8, 8.8, 30.0, amount=15.0)
    return fw.fixed_wing_points(
        [start, takeoff, _pt(2, 16, 8.8, 1600.0, 60.0)],
        ground_alt_m=HOME.alt_amsl_m, climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, home_deg=(HOME.lat_deg, HOME.lon_deg),
        takeoff_heading_deg=heading_deg, heads_for_takeoff_position=heads_for_position,
    )  # fmt: skip


def test_arduplane_climbs_out_along_its_heading_whatever_the_items_position() -> None:
    pts = _flown(45.0, heads_for_position=False)
    climb = [p for p in pts if p.command == 22]
    end_e, end_n = _en(climb[-1])
    run_m = 30.0 / math.tan(math.radians(15.0))  # 112 m at the item's 15 deg
    assert end_e == pytest.approx(run_m / math.sqrt(2.0), abs=1.0)
    assert end_n == pytest.approx(run_m / math.sqrt(2.0), abs=1.0)
    assert climb[-1].alt_amsl_m == pytest.approx(HOME.alt_amsl_m + 30.0)


def test_without_a_heading_it_is_the_heading_to_the_next_waypoint() -> None:
    pts = _flown(None, heads_for_position=False)
    end_e, end_n = _en([p for p in pts if p.command == 22][-1])
    assert abs(end_e) < 2.0 and end_n == pytest.approx(112.0, abs=2.0)


def test_px4_still_heads_for_a_take_off_position_away_from_it() -> None:
    """PX4's runway take-off heads for the item's position (more than HERE_M away)."""
    pts = _flown(45.0, heads_for_position=True)
    climb = [p for p in pts if p.command == 22]  # its climb along the line to the position
    assert _en(climb[-1]) == pytest.approx((8.8, 8.8), abs=0.5)


async def test_serve_files_the_run_along_the_heading_the_plane_armed_with() -> None:
    """Through USM: the heading of the status before arming is the run's; once armed, a new
    heading (the plane turning in flight) does not move it."""
    home = t.HOME
    usm = Usm(Airspace(), ManualClock(1000.0))
    usm.attach_vehicles(t._Port(t._mission()))
    usm.on_vehicle(t._Info(key=t._Key(1)))
    status = VehicleStatus(
        sys_id=SysId(1), t_s=1000.0, autopilot=Autopilot.ARDUPILOT, mode=FlightMode.MISSION,
        mission_total=7, home=home, position=home, gnss_fix_type=3, heading_deg=90.0,
    )  # fmt: skip
    usm.on_status(status)
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    climb = op.plan.waypoints[2]  # from where it stands, the roll, the climb's end: east
    k = math.cos(math.radians(home.lat_deg))
    assert (climb.lon_deg - home.lon_deg) * 111_320.0 * k == pytest.approx(112.0, abs=1.0)
    assert (climb.lat_deg - home.lat_deg) * M_LAT == pytest.approx(0.0, abs=1.0)


async def test_a_plane_first_heard_armed_on_the_ground_rolls_along_its_heading_then() -> None:
    """A serve restarted while the plane stood parked first heard it armed, at its take-off
    (the soak's PX4 plane after a kill -9: no status before the arming); on the ground its
    heading is still its run's. Filed with none, it climbed out towards its next waypoint
    from where it stood across its run (UAS_IN_CV 13.3 m as it rolled)."""
    home = t.HOME
    usm = Usm(Airspace(), ManualClock(1000.0))
    usm.attach_vehicles(t._Port(t._mission()))
    usm.on_vehicle(t._Info(key=t._Key(1)))
    first = VehicleStatus(
        sys_id=SysId(1), t_s=1000.0, autopilot=Autopilot.ARDUPILOT, mode=FlightMode.HOLD,
        armed=True, landed=True, mission_total=7, home=home, position=home, gnss_fix_type=3,
    )  # fmt: skip
    usm.on_status(first)  # armed, no heading yet (no GLOBAL_POSITION_INT since the restart)
    await usm.drain()
    usm.on_status(dataclasses.replace(first, mode=FlightMode.MISSION, heading_deg=90.0))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    climb = op.plan.waypoints[2]  # from where it stands, the roll, the climb's end: east
    k = math.cos(math.radians(home.lat_deg))
    assert (climb.lon_deg - home.lon_deg) * 111_320.0 * k == pytest.approx(112.0, abs=1.0)
    assert (climb.lat_deg - home.lat_deg) * M_LAT == pytest.approx(0.0, abs=1.0)
