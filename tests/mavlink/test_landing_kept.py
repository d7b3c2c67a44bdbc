"""No UTM plan removes a landing (issue 31.4): a mission that lands with NAV_LAND (PX4's
plane and quad, ArduPilot without DO_LAND_START) or NAV_VTOL_LAND keeps its approach and
landing item, at their places and in their frames, in every plan uploaded to the vehicle.

The nuisance soak's PX4 SIH plane got a back_to_plan whose last waypoint was its landing
point on the ground, sent as a NAV_WAYPOINT: it circled 0-4 m above the ground."""

from __future__ import annotations

from typing import Any

from adapters.mavlink import plan_to_mission_items
from adapters.mavlink.landing import CORRIDOR_M, cut_landing, plan_mission
from adapters.mavlink.mission import (
    MAV_CMD_DO_LAND_START,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_LOITER_TO_ALT,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_VTOL_LAND,
    MAV_CMD_NAV_WAYPOINT,
    MissionItem,
    current_seq,
    landing_sequence,
)
from gcs_utm.model import Autopilot, FlightPlan, OperationId, SysId, VehicleKind, Waypoint4D

LAT0, LON0, GROUND_M = 45.4671160, -73.7578370, 32.34  # PX4 SIH's home
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0 * 0.70225  # cos(45.467 deg)
NAV_LOITER_TIME = 19


def _deg(east_m: float, north_m: float) -> tuple[float, float]:
    return LAT0 + north_m / _M_PER_DEG_LAT, LON0 + east_m / _M_PER_DEG_LON


def _item(seq: int, command: int, east: float, north: float, agl: float, **kw: Any) -> MissionItem:
    lat, lon = _deg(east, north)
    return MissionItem(
        seq=seq, command=command, frame=kw.pop("frame", 5), x=round(lat * 1e7),
        y=round(lon * 1e7), z=kw.pop("z", GROUND_M + agl), **kw,
    )  # fmt: skip


def _px4_plane() -> list[MissionItem]:
    """The nuisance soak's PX4 plane (tests/autopilot/nuisance_fleet.py): runway take-off
    250 m north, 700 m north at 40 m, a 20 s loiter, the approach waypoint at 30 m and
    NAV_LAND 300 m south of home, AMSL (global frame)."""
    return [
        _item(0, MAV_CMD_NAV_TAKEOFF, 0.0, 250.0, 30.0, param1=15.0),
        _item(1, MAV_CMD_NAV_WAYPOINT, 0.0, 700.0, 40.0),
        _item(2, NAV_LOITER_TIME, -300.0, 700.0, 40.0, param1=20.0),
        _item(3, MAV_CMD_NAV_WAYPOINT, -300.0, 300.0, 30.0),
        _item(4, MAV_CMD_NAV_LAND, 0.0, -300.0, 0.0),
    ]


def _wp(east: float, north: float, agl: float, t_s: float) -> Waypoint4D:
    lat, lon = _deg(east, north)
    return Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=GROUND_M + agl, t_s=t_s)


def _plan(*wps: Waypoint4D) -> FlightPlan:
    return FlightPlan(operation_id=OperationId("plane"), version=3, waypoints=wps)


def _build(autopilot: Autopilot, kind: VehicleKind) -> Any:
    def build(part: FlightPlan, start: int) -> list[MissionItem]:
        return plan_to_mission_items(
            part, autopilot, start_index=start, kind=kind, min_speed_mps=10.0
        )

    return build


def _place(it: MissionItem) -> tuple[int, int, int, float, int]:
    return (it.command, it.x, it.y, round(it.z, 2), it.frame)


def test_px4_landing_is_its_approach_and_nav_land() -> None:
    mission = _px4_plane()
    assert landing_sequence(mission, Autopilot.PX4) == mission[3:]


def test_back_to_plan_keeps_the_px4_planes_nav_land_at_its_place() -> None:
    """back_to_plan from the loiter: to the approach waypoint, then the landing point on the
    ground (the filed plan's last waypoint). Uploaded: the approach and NAV_LAND themselves,
    no waypoint on the ground."""
    mission = _px4_plane()
    plan = _plan(_wp(-250.0, 650.0, 40.0, 100.0), _wp(-300.0, 300.0, 30.0, 125.0),
                 _wp(0.0, -300.0, 0.0, 170.0))  # fmt: skip
    items = plan_mission(
        plan,
        landing_sequence(mission, Autopilot.PX4),
        _build(Autopilot.PX4, VehicleKind.FIXED_WING),
        start_index=1,
        kind=VehicleKind.FIXED_WING,
    )
    assert [_place(i) for i in items[-2:]] == [_place(mission[3]), _place(mission[4])]
    assert items[-1].command == MAV_CMD_NAV_LAND
    ground = [i for i in items if i.command == MAV_CMD_NAV_WAYPOINT and i.z < GROUND_M + 5.0]
    assert ground == [], "a landing sent as a waypoint on the ground"
    assert [i.command for i in items].count(MAV_CMD_NAV_WAYPOINT) == 2  # start, approach
    assert [i.seq for i in items] == list(range(len(items)))
    assert items[current_seq(items)].command == MAV_CMD_NAV_WAYPOINT  # the plan's start


def test_a_plan_that_starts_on_the_approach_starts_at_nav_land() -> None:
    """The plane is on its landing line (between the approach waypoint and NAV_LAND) when the
    plan is made: the plan is its position, the point of the line it returns to, and the
    landing point. It goes on landing: NAV_LAND current, the approach before it (PX4 takes the
    item before NAV_LAND as the approach entrance and checks its glide slope)."""
    mission = _px4_plane()
    plan = _plan(_wp(-160.0, 20.0, 18.0, 200.0), _wp(-150.0, 0.0, 15.0, 201.5),
                 _wp(0.0, -300.0, 0.0, 225.0))  # fmt: skip
    items = plan_mission(
        plan,
        landing_sequence(mission, Autopilot.PX4),
        _build(Autopilot.PX4, VehicleKind.FIXED_WING),
        start_index=1,
        kind=VehicleKind.FIXED_WING,
    )
    assert [_place(i) for i in items[-2:]] == [_place(mission[3]), _place(mission[4])]
    assert items[current_seq(items)].command == MAV_CMD_NAV_LAND
    assert sum(i.current for i in items) == 1


def test_a_plan_over_the_landing_is_flown_then_the_landing() -> None:
    """A plan that crosses the landing line above its approach (at 60 m) is not the landing:
    flown as planned, then the approach and NAV_LAND (a fixed wing circles at a plan's end)."""
    mission = _px4_plane()
    plan = _plan(_wp(-300.0, 300.0, 60.0, 0.0), _wp(0.0, -300.0, 60.0, 45.0))
    landing = landing_sequence(mission, Autopilot.PX4)
    cut = cut_landing(plan, landing, 0)
    assert not cut.reaches and cut.plan == plan
    items = plan_mission(
        plan, landing, _build(Autopilot.PX4, VehicleKind.FIXED_WING),
        kind=VehicleKind.FIXED_WING,
    )  # fmt: skip
    assert [i.command for i in items][-2:] == [MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LAND]
    assert abs(items[-3].z - (GROUND_M + 60.0)) < 0.01  # the plan's last point


def test_the_corridor_is_horizontal_and_narrow() -> None:
    """A point beside the landing line (more than CORRIDOR_M off it) is not on it."""
    landing = landing_sequence(_px4_plane(), Autopilot.PX4)
    beside = _plan(_wp(-150.0 + CORRIDOR_M + 3.0, 0.0, 15.0, 0.0))
    on = _plan(_wp(-150.0 + CORRIDOR_M - 3.0, 0.0, 15.0, 0.0))
    assert not cut_landing(beside, landing, 0).reaches
    assert cut_landing(on, landing, 0).join == 1  # the sequence's NAV_LAND


def test_a_multirotor_keeps_its_landing_only_where_its_plan_goes() -> None:
    """A quad's plan that reaches its landing lands with NAV_LAND (not a waypoint on the
    ground); one that ends elsewhere (a hold, a landing site) ends there, as planned."""
    mission = [
        _item(0, MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 30.0),
        _item(1, MAV_CMD_NAV_WAYPOINT, 0.0, 200.0, 30.0),
        _item(2, MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 30.0),
        _item(3, MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0),
    ]
    landing = landing_sequence(mission, Autopilot.PX4)
    assert landing == mission[2:]
    build = _build(Autopilot.PX4, VehicleKind.MULTIROTOR)
    home = _plan(_wp(0.0, 200.0, 30.0, 0.0), _wp(0.0, 0.0, 30.0, 25.0), _wp(0.0, 0.0, 0.0, 40.0))
    items = plan_mission(home, landing, build, kind=VehicleKind.MULTIROTOR)
    assert [_place(i) for i in items[-2:]] == [_place(mission[2]), _place(mission[3])]
    hold = _plan(_wp(0.0, 200.0, 30.0, 0.0), _wp(100.0, 200.0, 30.0, 20.0))
    items = plan_mission(hold, landing, build, kind=VehicleKind.MULTIROTOR)
    assert MAV_CMD_NAV_LAND not in [i.command for i in items]


def test_ardupilot_nav_land_vtol_land_and_land_start() -> None:
    """ArduPilot: seq 0 is home, never an approach; a relative-altitude NAV_LAND keeps its
    frame; NAV_VTOL_LAND is a landing; DO_LAND_START starts the sequence when present."""
    home = _item(0, MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0, frame=0)
    rel = {"frame": 3}
    approach = _item(2, MAV_CMD_NAV_LOITER_TO_ALT, 0.0, 600.0, 0.0, z=40.0, **rel)
    land = _item(3, MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0, z=0.0, **rel)
    takeoff = _item(1, MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, z=30.0, **rel)
    assert landing_sequence([home, takeoff, approach, land], Autopilot.ARDUPILOT) == [
        approach, land
    ]  # fmt: skip
    bare = _item(1, MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0, z=0.0, **rel)
    assert landing_sequence([home, bare], Autopilot.ARDUPILOT) == [bare]
    vtol = _item(3, MAV_CMD_NAV_VTOL_LAND, 0.0, 0.0, 0.0, z=0.0, **rel)
    assert landing_sequence([home, takeoff, approach, vtol], Autopilot.ARDUPILOT) == [
        approach, vtol
    ]  # fmt: skip
    start = _item(2, MAV_CMD_DO_LAND_START, 0.0, 800.0, 0.0, z=0.0, **rel)
    seq = [home, takeoff, start, approach, land]
    assert landing_sequence(seq, Autopilot.ARDUPILOT) == seq[2:]
    # relative altitudes resolved with home: a plan point at the landing point is its landing
    plan = _plan(_wp(0.0, 900.0, 60.0, 0.0), _wp(0.0, 600.0, 40.0, 15.0), _wp(0.0, 0.0, 0.0, 50.0))
    items = plan_mission(
        plan, [approach, land], _build(Autopilot.ARDUPILOT, VehicleKind.FIXED_WING),
        kind=VehicleKind.FIXED_WING, home_alt_m=GROUND_M,
    )  # fmt: skip
    assert [_place(i) for i in items[-2:]] == [_place(approach), _place(land)]


async def test_a_hub_upload_to_a_vehicle_with_nav_land_keeps_it(env: Any) -> None:
    """Through the hub: a vehicle whose mission lands with NAV_LAND (no DO_LAND_START) gets
    a plan ending at its landing point; its copy ends with the approach and NAV_LAND at their
    places, and again after a second plan (the landing read back from the first)."""
    v = await env.vehicle(7)
    mission = _px4_plane()
    assert (await env.hub.upload_items(SysId(7), mission, set_mission_mode=False)).ok
    await env.hub.download_mission(SysId(7))
    plan = _plan(_wp(-250.0, 650.0, 40.0, 100.0), _wp(-300.0, 300.0, 30.0, 125.0),
                 _wp(0.0, -300.0, 0.0, 170.0))  # fmt: skip
    for _ in range(2):
        res = await env.hub.upload_plan(SysId(7), plan, start_index=1)
        assert res.ok and res.verified, res
        got = [(m.command, m.x, m.y, round(m.z, 2)) for m in v.mission]
        assert got[-2:] == [p[:4] for p in map(_place, mission[3:])], got
        assert [m.command for m in v.mission].count(MAV_CMD_NAV_LAND) == 1
        low = [m.seq for m in v.mission if m.command == MAV_CMD_NAV_WAYPOINT and m.z < 40.0]
        assert low == [], f"waypoints on the ground: {got}"
    v.close()
