"""A plan uploaded to an ArduPlane keeps the pilot's loiter as a loiter item (issue 31.4):
its filed circle's points are not sent as waypoints, which ArduPlane accepts WP_RADIUS
early and flies on a wider, ragged ring (adapters/mavlink/loiter_kept.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import pytest

from adapters.mavlink.loiter_kept import (
    MAV_CMD_NAV_LOITER_TIME,
    MAV_CMD_NAV_LOITER_TURNS,
    keep_loiters,
    mission_loiters,
)
from adapters.mavlink.mission import (
    MAV_CMD_DO_LAND_START,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_WAYPOINT,
    MissionItem,
    plan_to_mission_items,
    start_item,
)
from adapters.mavlink.transfer import UploadResult
from adapters.mavlink.upload import Uploads
from gcs_utm.model import Autopilot, FlightPlan, OperationId, Position, VehicleKind
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.fixed_wing_loiter import STEP_RAD
from gcs_utm.services.mission_points import mission_is_plan, mission_points, plan_from_points

LAT0, LON0, GROUND_M = 47.397, 8.5456, 488.0
RADIUS_M = 80.0  # ArduPlane's WP_LOITER_RAD in its SITL defaults
REL = 3  # MAV_FRAME_GLOBAL_RELATIVE_ALT
HOME = Position(lat_deg=LAT0, lon_deg=LON0, alt_amsl_m=GROUND_M)


def _item(seq: int, command: int, east: float, north: float, agl: float, **kw: Any) -> MissionItem:
    lat = LAT0 + north / 110_540.0
    lon = LON0 + east / (111_320.0 * math.cos(math.radians(LAT0)))
    return MissionItem(
        seq=seq, command=command, frame=REL, x=round(lat * 1e7), y=round(lon * 1e7), z=agl, **kw
    )


def _mission(command: int = MAV_CMD_NAV_LOITER_TIME, amount: float = 20.0) -> list[MissionItem]:
    """The soak's ArduPlane mission as ArduPlane reads it back: home, take-off, 900 m north at
    60 m, a 20 s NAV_LOITER_TIME 500 m west (param3 1: no radius, clockwise), DO_LAND_START,
    the approach, NAV_LAND at home."""
    return [
        MissionItem(seq=0, command=MAV_CMD_NAV_WAYPOINT, x=round(LAT0 * 1e7),
                    y=round(LON0 * 1e7), z=GROUND_M),
        MissionItem(seq=1, command=22, frame=REL, param1=15.0, z=30.0),
        _item(2, MAV_CMD_NAV_WAYPOINT, 0.0, 900.0, 60.0),
        _item(3, command, -500.0, 900.0, 60.0, param1=amount, param3=1.0),
        _item(4, MAV_CMD_DO_LAND_START, -500.0, 0.0, 0.0),
        _item(5, MAV_CMD_NAV_WAYPOINT, -400.0, -400.0, 30.0),
        _item(6, MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0),
    ]  # fmt: skip


def _filed(mission: list[MissionItem]) -> FlightPlan:
    """The plan serve files for that mission (vehicle_ops: its points as ArduPlane flies them)."""
    points = mission_points(mission, home=HOME, cruise_speed_mps=22.0, skip_first=True)
    assert points is not None
    flown = fw.fixed_wing_points(
        points, ground_alt_m=GROUND_M, climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=RADIUS_M, home_deg=(LAT0, LON0), takeoff_heading_deg=0.0,
        heads_for_takeoff_position=False, turn_after_takeoff=True,
    )  # fmt: skip
    plan = plan_from_points(flown, OperationId("sys1"), t_s=0.0)
    assert plan is not None
    return plan


def _on_circle(items: list[MissionItem], loiter: MissionItem) -> list[int]:
    """The seqs of waypoints within 1 m of the loiter's 80 m circle (seq 0 is home)."""
    k = math.cos(math.radians(LAT0))
    out = []
    for it in items:
        east = (it.y - loiter.y) / 1e7 * 111_320.0 * k
        north = (it.x - loiter.x) / 1e7 * 110_540.0
        on = abs(math.hypot(east, north) - RADIUS_M) < 1.0
        if it.seq > 0 and it.command == MAV_CMD_NAV_WAYPOINT and on:
            out.append(it.seq)
    return out


def _entry_only(items: list[MissionItem]) -> bool:
    """Of the circle's points only its entry is sent: the waypoint before the loiter item
    (its speed item between them), 5 cm inside the circle."""
    loiter = next(k for k, it in enumerate(items) if it.command in (18, 19))
    on = _on_circle(items, items[loiter])
    return on == [loiter - 2] and items[loiter - 1].command == 178


def _echo(items: list[MissionItem], plan: FlightPlan) -> bool:
    """Whether serve (vehicle_ops) takes ``items`` read back from the vehicle, from their
    current item on, for ``plan``: the upload's echo, not a new mission of the pilot's."""
    points = mission_points(items, home=HOME, cruise_speed_mps=22.0, skip_first=True)
    assert points is not None
    flown = fw.fixed_wing_points(
        points, ground_alt_m=GROUND_M, climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=RADIUS_M, home_deg=(LAT0, LON0), takeoff_heading_deg=0.0,
        heads_for_takeoff_position=False, turn_after_takeoff=True,
    )  # fmt: skip
    current = next(it.seq for it in items if it.current)
    return mission_is_plan([p for p in flown if p.seq >= current], plan)


@dataclass
class _State:
    """What Uploads.upload_plan reads of a vehicle."""

    mission: list[MissionItem]
    kind: VehicleKind = VehicleKind.FIXED_WING
    autopilot: Autopilot = Autopilot.ARDUPILOT
    home: Position = field(default_factory=lambda: HOME)
    key: str = "plane"


class _Transfers:
    """A hub's transfer part as far as upload_plan uses it before the mission protocol."""

    def __init__(self, state: _State) -> None:
        self.config = type("Cfg", (), {"max_speed_mps": 30.0})()
        self.link = type("Link", (), {"state": lambda _self, _sys_id: state})()


async def _uploaded(state: _State, plan: FlightPlan, start_index: int = 0) -> list[MissionItem]:
    """The items Uploads.upload_plan sends for ``plan`` (the protocol itself not run)."""
    sent: list[list[MissionItem]] = []

    async def capture(_self: Uploads, _key: Any, items: list[MissionItem], **_kw: Any) -> Any:
        sent.append(items)
        return UploadResult(ok=True, verified=True, attempts=1, items=len(items), duration_s=0.0)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Uploads, "upload_items", capture)
        await Uploads(_Transfers(state)).upload_plan(  # type: ignore[arg-type]
            "plane", plan, start_index=start_index, min_speed_mps=10.0
        )
    return sent[0]


async def test_an_arduplane_upload_keeps_the_loiter_item() -> None:
    """The filed plan uploaded whole (a re-plan before the loiter): the pilot's loiter item
    as it is (its place, 20 s, param3 1), none of its circle's points as waypoints, and the
    landing sequence after it."""
    mission = _mission()
    plan = _filed(mission)
    loiter = mission[3]
    assert len(_on_circle(plan_to_mission_items(plan, Autopilot.ARDUPILOT), loiter)) >= 8
    items = await _uploaded(_State(mission), plan)
    loiters = [it for it in items if it.command == MAV_CMD_NAV_LOITER_TIME]
    assert [replace(it, seq=0) for it in loiters] == [replace(loiter, seq=0)]
    assert _entry_only(items)
    assert _echo(items, plan)
    assert [it.command for it in items[-3:]] == [MAV_CMD_DO_LAND_START, 16, MAV_CMD_NAV_LAND]
    assert [it.seq for it in items] == list(range(len(items)))


async def test_a_plan_from_the_circle_starts_at_the_loiter_and_leaves_where_it_does() -> None:
    """A back_to_plan of a plane on its circle starts at the loiter item (current; ArduPlane
    restarts its goal): with the pilot's 20 s when they end within the turn before the plan's
    exit from the circle, else with the time that ends half a turn before it, so the plane
    leaves where the plan does (after the goal it goes on round to its exit heading)."""
    mission = _mission()
    plan = _filed(mission)
    on = [k for k, w in enumerate(plan.waypoints) if _circle_distance(w) < 1.0]
    per_step_s = (plan.waypoints[on[-1]].t_s - plan.waypoints[on[0]].t_s) / (len(on) - 1)
    assert 20.0 / per_step_s * STEP_RAD < 2.0 * math.pi < len(on) * STEP_RAD  # one turn after
    for steps_left, want_s in ((len(on) // 2, 20.0), (12, 4.0 * per_step_s), (4, 0.0)):
        rest = FlightPlan(
            operation_id=plan.operation_id,
            version=2,
            waypoints=plan.waypoints[on[-1] - steps_left :],
        )
        items = await _uploaded(_State(mission), rest)
        seq, _ = start_item(items, Autopilot.ARDUPILOT)
        assert _on_circle(items, mission[3]) == [seq]  # the entry, then the loiter
        assert items[seq + 2].command == MAV_CMD_NAV_LOITER_TIME, steps_left
        assert items[seq + 2].param1 == round(want_s), (steps_left, items[seq + 2].param1)
        assert _entry_only(items)
        assert _echo(items, rest)  # serve's model of the mission read back is the plan


def _circle_distance(w: Any) -> float:
    k = math.cos(math.radians(LAT0))
    east = (w.lon_deg - (LON0 - 500.0 / (111_320.0 * k))) * 111_320.0 * k
    north = (w.lat_deg - (LAT0 + 900.0 / 110_540.0)) * 110_540.0
    return abs(math.hypot(east, north) - RADIUS_M)


def test_loiter_turns_keep_whole_turns_and_other_vehicles_their_waypoints() -> None:
    """NAV_LOITER_TURNS: the whole turns of the plan's sweep; the item as it is when the plan
    holds its whole circle. Only loiters with a position are looked for."""
    mission = _mission(MAV_CMD_NAV_LOITER_TURNS, 2.0)
    plan = _filed(mission)
    loiters = mission_loiters(mission)
    assert [it.seq for it in loiters] == [3]
    items = plan_to_mission_items(plan, Autopilot.ARDUPILOT, kind=VehicleKind.FIXED_WING)
    kept = keep_loiters(plan, items, loiters, GROUND_M)
    assert [it.param1 for it in kept if it.command == MAV_CMD_NAV_LOITER_TURNS] == [2.0]
    assert keep_loiters(plan, items, [], GROUND_M) == items
    assert keep_loiters(plan, items, loiters, None) == items  # relative: no home, not found


async def test_a_px4_plane_and_a_multirotor_are_not_changed() -> None:
    mission = _mission()
    plan = _filed(mission)
    for state in (
        _State(mission, autopilot=Autopilot.PX4),
        _State(mission, kind=VehicleKind.MULTIROTOR),
    ):
        items = await _uploaded(state, plan)
        assert not any(it.command == MAV_CMD_NAV_LOITER_TIME for it in items)


async def test_a_back_to_plan_joining_on_a_chord_starts_at_the_loiter() -> None:
    """back_to_plan's plan: the plane's position (off the ring), the point of the plan nearest
    it (on a chord between two circle points, 1.5 m inside the circle), then the plan: the
    plane's position is flown first, then the loiter item; no circle point is sent."""
    mission = _mission()
    plan = _filed(mission)
    on = [k for k, w in enumerate(plan.waypoints) if _circle_distance(w) < 1.0]
    a, b = plan.waypoints[on[-8]], plan.waypoints[on[-7]]
    q = replace(a, lat_deg=(a.lat_deg + b.lat_deg) / 2, lon_deg=(a.lon_deg + b.lon_deg) / 2)
    assert 1.0 < _circle_distance(q) < 2.0
    outside = replace(a, lat_deg=a.lat_deg + 12.0 / 110_540.0, t_s=a.t_s - 1.0)
    wps = (outside, q, *plan.waypoints[on[-7] :])
    items = await _uploaded(_State(mission), replace(plan, waypoints=wps), start_index=1)
    commands = [it.command for it in items]
    # the plane's position, the chord's point, the circle's point after it (its entry), the
    # loiter
    assert commands[:8] == [16, 16, 178, 16, 178, 16, 178, MAV_CMD_NAV_LOITER_TIME], commands
    assert _entry_only(items)
    assert _echo(items, replace(plan, waypoints=wps))
    seq, _ = start_item(items, Autopilot.ARDUPILOT)
    assert items[seq] == items[3]  # the chord's point, then the entry and the loiter
