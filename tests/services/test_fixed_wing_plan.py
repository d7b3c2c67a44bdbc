"""A fixed wing's mission filed as it flies it (issue 31.4): the take-off is a climb-out
along the heading to the next waypoint, not a vertical climb at home; loiters are circles;
the landing sequence is a descent along the track, and a UTM plan uploaded with the pilot's
landing sequence kept at its end is the plan (not a new mission of the pilot's)."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    OperationId,
    Position,
    SysId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mission_points import (
    NavPoint,
    mission_is_plan,
    mission_points,
    plan_from_points,
)
from gcs_utm.services.usm import Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import FakeVehicles

HOME = Position(lat_deg=40.6597, lon_deg=-3.5969, alt_amsl_m=675.0)
M_PER_DEG_LAT = 110_540.0


@dataclass
class _Item:
    command: int
    x: int = 0
    y: int = 0
    z: float = 0.0
    frame: int = 3  # relative altitude, as ArduPilot's ground stations send it
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    seq: int = 0


def _north(m: float) -> int:
    return round((HOME.lat_deg + m / M_PER_DEG_LAT) * 1e7)


def _east(m: float) -> int:
    k = math.cos(math.radians(HOME.lat_deg))
    return round((HOME.lon_deg + m / (111_320.0 * k)) * 1e7)


def _north_m(p: NavPoint | Waypoint4D) -> float:
    return (p.lat_deg - HOME.lat_deg) * M_PER_DEG_LAT


def _mission() -> list[_Item]:
    """ArduPlane's typical mission: home, take-off to 30 m, a loiter-to-alt climb to 60 m,
    two waypoints, then DO_LAND_START, the approach and NAV_LAND at home."""
    lat, lon = _e7(HOME.lat_deg), _e7(HOME.lon_deg)
    items = [
        _Item(16, lat, lon, HOME.alt_amsl_m, frame=0),
        _Item(22, z=30.0, param1=15.0),
        _Item(16, _north(800.0), lon, 30.0),
        _Item(31, _north(800.0), lon, 60.0, param2=80.0),
        _Item(16, _north(800.0), _east(-800.0), 60.0),
        _Item(189, _north(0.0), _east(-800.0)),
        _Item(16, _north(-400.0), _east(-400.0), 30.0),
        _Item(21, lat, lon, 0.0),
    ]
    return [_Item(**{**it.__dict__, "seq": k}) for k, it in enumerate(items)]


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def _points() -> list[NavPoint]:
    pts = mission_points(_mission(), home=HOME, cruise_speed_mps=15.0, skip_first=True)
    assert pts is not None
    return fw.fixed_wing_points(
        pts, ground_alt_m=HOME.alt_amsl_m, climb_rate_mps=3.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0,
    )  # fmt: skip


def test_takeoff_is_a_climb_out_along_the_heading_to_the_next_waypoint() -> None:
    pts = mission_points(_mission(), home=HOME, cruise_speed_mps=15.0, skip_first=True)
    assert pts is not None
    assert _north_m(pts[0]) == pytest.approx(0.0, abs=0.1)  # the multirotor model: at home
    plane = _points()
    roll, takeoff = plane[0], plane[1]
    # the ground roll: a third of the run, on the ground (ArduPlane: lift-off 40 m out)
    assert not roll.explicit and roll.alt_amsl_m == pytest.approx(HOME.alt_amsl_m)
    assert _north_m(roll) == pytest.approx(fw.ROLL_FRACTION * 112.0, abs=1.0)
    # 30 m at the item's 15 deg pitch: the climb ends 112 m north of home (ArduPlane 4.6:
    # 30 m reached 111 m out, ground roll included)
    assert _north_m(takeoff) == pytest.approx(30.0 / math.tan(math.radians(15.0)), abs=1.0)
    assert takeoff.lon_deg == pytest.approx(HOME.lon_deg, abs=1e-7)
    assert takeoff.alt_amsl_m == pytest.approx(705.0)


def test_a_takeoff_at_the_launch_position_is_a_climb_out_along_the_heading() -> None:
    """QGroundControl gives a plane's NAV_TAKEOFF the launch position; ArduPlane climbs out
    along its heading all the same. Filed as a vertical climb at home (the item 1.8 m from
    the reported home), the rolling ArduPlane of the nuisance soak opened UAS_OUT_OV 3 s into
    its take-off, and the auto-accepted HOLD was sent to a plane climbing out."""
    items = _mission()
    items[1] = _Item(22, _north(1.8), _e7(HOME.lon_deg), 30.0, param1=15.0, seq=1)
    pts = mission_points(items, home=HOME, cruise_speed_mps=15.0, skip_first=True)
    assert pts is not None
    plane = fw.fixed_wing_points(
        pts, ground_alt_m=HOME.alt_amsl_m, climb_rate_mps=3.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, home_deg=(HOME.lat_deg, HOME.lon_deg),
    )  # fmt: skip
    assert plane[:2] == _points()[:2]  # the same ground roll and climb-out as "here"


def test_a_takeoff_with_a_position_is_a_climb_out_towards_it() -> None:
    """PX4: NAV_TAKEOFF carries the position its runway take-off heads for (250 m north, at
    30 m; PX4 reads it back without a pitch). Measured on PX4 v1.15.2 SIH: lift-off about
    18 m out, 30 m reached 95-99 m out; the straight line from home to the
    take-off position put the climbing plane 18-28 m above its plan. The climb-out at 5 m/s
    (FW_T_CLMB_MAX) at the minimum airspeed (0.7 x 22 m/s): 92 m."""
    px4 = [
        _Item(22, _north(250.0), _e7(HOME.lon_deg), HOME.alt_amsl_m + 30.0, frame=0),
        _Item(16, _north(1000.0), _e7(HOME.lon_deg), HOME.alt_amsl_m + 30.0, frame=0, seq=1),
    ]  # fmt: skip
    pts = mission_points(px4, home=HOME, cruise_speed_mps=22.0, skip_first=False)
    assert pts is not None
    plane = fw.fixed_wing_points(
        pts, ground_alt_m=HOME.alt_amsl_m, climb_rate_mps=3.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, home_deg=(HOME.lat_deg, HOME.lon_deg),
    )  # fmt: skip
    run_m = 30.0 * 0.7 * 22.0 / 5.0
    # PX4 completes the take-off at its altitude and flies for the next waypoint from there
    # (fixed_wing_runway.px4_takeoff): on the line here, not over the take-off position
    roll, climbed, leg = plane
    assert _north_m(roll) == pytest.approx(fw.ROLL_FRACTION * run_m, abs=1.0)
    assert roll.alt_amsl_m == pytest.approx(HOME.alt_amsl_m)
    assert _north_m(climbed) == pytest.approx(run_m, abs=1.0)
    assert climbed.alt_amsl_m == pytest.approx(HOME.alt_amsl_m + 30.0)
    assert not roll.explicit and not climbed.explicit  # modelled: never compared
    assert _north_m(leg) == pytest.approx(1000.0, abs=0.5)


def test_loiter_to_alt_is_a_climbing_circle_and_landing_is_flagged() -> None:
    plane = _points()
    circle = [p for p in plane if p.command == 31]
    centre = (HOME.lat_deg + 800.0 / M_PER_DEG_LAT, HOME.lon_deg)
    k = math.cos(math.radians(centre[0]))
    radii = [
        math.hypot(
            (p.lat_deg - centre[0]) * M_PER_DEG_LAT,
            (p.lon_deg - centre[1]) * 111_320.0 * k,
        )
        for p in circle
    ]
    assert all(r == pytest.approx(80.0, abs=0.5) for r in radii)
    # 30 m at 3 m/s: 16 m of it on the 80 m to the circle (3 m/s at 15 m/s), 14 m on it
    # (4.7 s of a 33.5 s turn: 50 deg), then on round until it heads for the next waypoint
    alts = [p.alt_amsl_m for p in circle]
    assert alts[0] == pytest.approx(721.0) and alts[-1] == pytest.approx(735.0)
    assert alts == sorted(alts)
    assert alts.index(735.0) == 3  # 50 deg: reached at the 3rd step of 22.5 deg
    landing = [p.seq for p in plane if p.landing]
    assert landing == [6, 7]  # the approach and NAV_LAND (DO_LAND_START has no point)
    plan = plan_from_points(plane, OperationId("p"), t_s=0.0)
    assert plan is not None
    # the landing is a descent along the track: 30 m -> ground over 566 m
    assert plan.waypoints[-1].alt_amsl_m == pytest.approx(HOME.alt_amsl_m)
    assert mission_is_plan(plane, plan)


def test_a_utm_plan_with_the_landing_sequence_kept_is_the_plan() -> None:
    """The mission read back after an upload ends with the pilot's landing sequence: its
    landing points are not compared with the plan (else the echo is a new pilot mission)."""
    items = _mission()
    utm = FlightPlan(
        operation_id=OperationId("p"),
        version=2,
        waypoints=tuple(
            Waypoint4D(
                lat_deg=HOME.lat_deg + n / M_PER_DEG_LAT,
                lon_deg=HOME.lon_deg,
                alt_amsl_m=HOME.alt_amsl_m + 60.0,
                t_s=n,
            )
            for n in (300.0, 600.0)
        ),
    )
    uploaded = [
        _Item(16, _e7(HOME.lat_deg), _e7(HOME.lon_deg), HOME.alt_amsl_m, frame=0, seq=0),
        *(
            _Item(16, _e7(w.lat_deg), _e7(w.lon_deg), w.alt_amsl_m, frame=0, seq=k)
            for k, w in enumerate(utm.waypoints, start=1)
        ),
        *(_Item(**{**it.__dict__, "seq": it.seq - 2}) for it in items[5:]),
    ]
    pts = mission_points(uploaded, home=HOME, cruise_speed_mps=15.0, skip_first=True)
    assert pts is not None and any(p.landing for p in pts)
    assert mission_is_plan(pts, utm)


class _Port(FakeVehicles):
    def __init__(self, mission: list[_Item]) -> None:
        super().__init__()
        self.mission = mission

    async def download_mission(self, sys_id: SysId) -> list[_Item]:
        return list(self.mission)


@dataclass
class _Key:
    sys_id: int


@dataclass
class _Info:
    key: _Key
    autopilot: Autopilot = Autopilot.ARDUPILOT
    vehicle_kind: VehicleKind = VehicleKind.FIXED_WING


async def test_a_plane_on_the_ground_is_filed_with_its_climb_out() -> None:
    """ArduPlane's mission filed on the ground: from where it stands to the end of its
    climb-out (north, along the runway to the first waypoint), not straight up at home."""
    clock = ManualClock(1000.0)
    usm = Usm(Airspace(), clock)
    usm.attach_vehicles(_Port(_mission()))
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(
        VehicleStatus(sys_id=SysId(1), t_s=1000.0, autopilot=Autopilot.ARDUPILOT,
                      mode=FlightMode.MISSION, mission_total=7, home=HOME, position=HOME,
                      gnss_fix_type=3)
    )  # fmt: skip
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    first, _roll, climb = op.plan.waypoints[:3]
    assert _north_m(first) == pytest.approx(0.0, abs=0.5) and first.t_s == 1000.0
    assert climb.alt_amsl_m == pytest.approx(HOME.alt_amsl_m + 30.0)
    assert _north_m(climb) == pytest.approx(112.0, abs=1.0)
    # without a pitch in the item: at the maximum climb rate (5 m/s) and the minimum speed
    no_pitch = _mission()
    no_pitch[1] = _Item(22, z=30.0, seq=1)
    pts = mission_points(no_pitch, home=HOME, cruise_speed_mps=15.0, skip_first=True)
    assert pts is not None
    out = fw.fixed_wing_points(
        pts, ground_alt_m=HOME.alt_amsl_m, climb_rate_mps=3.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0,
    )  # fmt: skip
    assert _north_m(out[1]) == pytest.approx(30.0 * 0.7 * 15.0 / 5.0, abs=1.0)


def test_a_plane_retimed_at_a_new_item_turns_round_the_waypoint_it_reached() -> None:
    """ArduPlane reports the next item 50 m before a waypoint (WP_RADIUS): re-timed from
    there straight to the next waypoint, the plan cut the corner that the plane flies round,
    and the plane was 41 m from it (UAS_OUT_OV) in its turn on the real ArduPlane."""
    lat, lon = HOME.lat_deg, HOME.lon_deg
    corner = NavPoint(2, lat + 800.0 / M_PER_DEG_LAT, lon, 725.0, 22.0, True)
    west = NavPoint(3, corner.lat_deg, _east(-800.0) / 1e7, 725.0, 22.0, True)
    at = Position(lat_deg=lat + 750.0 / M_PER_DEG_LAT, lon_deg=lon, alt_amsl_m=725.0)
    args = {"t_s": 100.0, "current_seq": 3, "position": at}
    plane = plan_from_points([corner, west], OperationId("p"), turn_from_m=80.0, **args)  # type: ignore[arg-type]
    assert plane is not None
    assert [round(_north_m(w)) for w in plane.waypoints] == [750, 800, 800]
    assert plane.waypoints[1].t_s == pytest.approx(100.0 + 50.0 / 22.0, abs=0.05)
    quad = plan_from_points([corner, west], OperationId("p"), **args)  # type: ignore[arg-type]
    assert quad is not None and [round(_north_m(w)) for w in quad.waypoints] == [750, 800]


def test_a_changed_landing_sequence_is_a_new_mission_for_a_plan_that_has_one() -> None:
    """A plan filed from the mission holds its landing: a pilot's new approach is a change."""
    plane = _points()
    plan = plan_from_points(plane, OperationId("p"), t_s=0.0)
    assert plan is not None and mission_is_plan(plane, plan)
    moved = [
        p.moved(p.lat_deg + 0.001, p.lon_deg, p.alt_amsl_m) if p.seq == 6 else p for p in plane
    ]
    assert not mission_is_plan(moved, plan)
