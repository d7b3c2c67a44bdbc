"""A fixed wing's plan is timed from its take-off run (issue 31). In the short nuisance soak
the PX4 plane's plan was timed from its arming while it stood 9 simulated s on the runway
until the pilot's MISSION_START: the plan had it rolling and climbing (UAS_IN_CV 10.9-12.2 m
on its first take-off). Re-timed when it has left where it armed by 5 m."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from gcs_utm.messages import FlightMode
from gcs_utm.model import Position, SysId, VehicleKind
from gcs_utm.services.takeoff_roll import RollWatch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_px4_runway_takeoff as rt
from test_vehicle_ops import HOME, NORTH_100M_E7, _Info, _Key, _relative_mission, _status, _usm


def _north(m: float) -> Position:
    return Position(lat_deg=HOME.lat_deg + m / 100.0 * NORTH_100M_E7 / 1e7,
                    lon_deg=HOME.lon_deg, alt_amsl_m=HOME.alt_amsl_m)  # fmt: skip


async def _first_wp_t(kind: VehicleKind) -> float:
    usm, port, clock = _usm()
    port.mission = _relative_mission(legs=2)  # take-off (here), 100 m north, 200 m north
    usm.on_vehicle(_Info(key=_Key(1), vehicle_kind=kind))
    usm.on_status(_status(1000.0, total=3, home=HOME, position=HOME, seq=0))
    await usm.drain()
    on = dict(total=3, home=HOME, seq=0, armed=True, mode=FlightMode.MISSION, landed=False)
    for t_s, north_m in ((1010.0, 0.0), (1014.0, 1.5), (1019.0, 2.0), (1019.5, 6.0)):
        clock.set(t_s)  # armed in mission mode: it stands (GNSS wander), then rolls at 1019.5
        usm.on_status(_status(t_s, position=_north(north_m), **on))  # type: ignore[arg-type]
        await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    return op.plan.waypoints[0].t_s


async def test_a_plane_standing_armed_is_timed_from_its_take_off_run() -> None:
    assert await _first_wp_t(VehicleKind.FIXED_WING) == 1019.5


async def test_a_multirotor_keeps_its_start() -> None:
    assert await _first_wp_t(VehicleKind.MULTIROTOR) == 1010.0


def test_a_vehicle_found_armed_is_not_watched() -> None:
    """A restarted service hearing a plane already armed (flying) times it as found flying."""
    watch = RollWatch()
    watch.update(armed=True, was_armed=False, position=HOME)
    assert not watch.rolled(_north(50.0))
    watch.update(armed=False, was_armed=True, position=HOME)
    watch.update(armed=True, was_armed=False, position=HOME)
    assert not watch.rolled(_north(3.0))
    assert watch.rolled(_north(6.0))
    assert not watch.rolled(_north(20.0))  # once


PARKED = json.loads(
    (Path(__file__).resolve().parents[1] / "data" / "flown" / "px4_plane_parked_yaw_off.json")
    .read_text()
)  # fmt: skip


def _pos(q: dict[str, float]) -> Position:
    return Position(lat_deg=q["lat_deg"], lon_deg=q["lon_deg"], alt_amsl_m=q["alt_amsl_m"])


def test_a_plane_stands_on_the_course_it_last_rolled_on() -> None:
    """The soak's PX4 plane reported a yaw 36 deg off as it armed after its landing (114.6,
    standing on 151 after the roll-out, and rolled along 151): its take-off planned from the
    course it last rolled on is within 6 m of it, from the reported yaw 16.8 m (UAS_IN_CV
    22.8 m)."""
    watch = RollWatch()
    watch.update(armed=False, was_armed=False, position=_pos(PARKED["landing"][0]))
    armed = False
    for q in PARKED["landing"]:  # the landing's roll-out, armed
        watch.update(armed=True, was_armed=armed, position=_pos(q))
        armed = True
    for _ in range(3):  # disarmed where it stopped: its position wanders, it stands
        watch.update(armed=False, was_armed=armed, position=_pos(PARKED["home"]))
        armed = False
    parked = watch.parked_heading_deg(PARKED["heading_deg"])
    assert parked is not None and abs(parked - 151.0) < 5.0
    assert RollWatch().parked_heading_deg(PARKED["heading_deg"]) == PARKED["heading_deg"]
    home = PARKED["home"]

    def worst_m(heading_deg: float) -> float:
        plan = rt._plan(heading_deg, PARKED)
        return max(rt._off_m(plan, q, home)[0] for q in PARKED["track"])

    assert worst_m(parked) < 6.0
    assert worst_m(PARKED["heading_deg"]) > 15.0
