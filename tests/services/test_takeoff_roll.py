"""A fixed wing's plan is timed from its take-off run (issue 31). In the short nuisance soak
the PX4 plane's plan was timed from its arming while it stood 9 simulated s on the runway
until the pilot's MISSION_START: the plan had it rolling and climbing (UAS_IN_CV 10.9-12.2 m
on its first take-off). Re-timed when it has left where it armed by 5 m."""

from __future__ import annotations

import sys
from pathlib import Path

from gcs_utm.messages import FlightMode
from gcs_utm.model import Position, SysId, VehicleKind
from gcs_utm.services.takeoff_roll import RollWatch

sys.path.insert(0, str(Path(__file__).resolve().parent))
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
