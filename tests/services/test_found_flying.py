"""A restarted serve and the vehicles it finds flying (issue 31's nuisance soak).

Measured on the soak (`tests/autopilot/test_nuisance_soak.py`, all four autopilots, speed 3):
serve killed with -9 while the PX4 plane flew its approach and restarted 2 s later; the new
life's mission download from the plane had not ended 16 s later, and until it did the plane
was judged by the previous life's plan from the store, timed on that life's clock (about 45 s
ahead of the new one's): UAS_OUT_OV 445.7 m (347.7 m in an earlier run), an auto-accepted
hold. A plan's times from another life cannot be trusted: the new life re-times the stored
plan from the vehicle's position at its first position, before any download.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import sys
from pathlib import Path

from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import FlightPlan, OperationId, Position, SysId, VehicleKind, Waypoint4D
from gcs_utm.services.found_flying import retimed_at

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_vehicle_ops import HOME, NORTH_100M_E7, _e7, _Info, _Item, _Key, _status, _usm


def _north(m: float, alt_m: float = 52.34) -> Position:
    return Position(
        lat_deg=HOME.lat_deg + m / 100.0 * NORTH_100M_E7 / 1e7,
        lon_deg=HOME.lon_deg,
        alt_amsl_m=alt_m,
    )


def _north_m(p: Waypoint4D | Position) -> float:
    return (p.lat_deg - HOME.lat_deg) * 1e7 / NORTH_100M_E7 * 100.0


def _east_m(p: Waypoint4D) -> float:
    return (p.lon_deg - HOME.lon_deg) * 111_320.0 * math.cos(math.radians(HOME.lat_deg))


def _wp(m: float, t_s: float) -> Waypoint4D:
    p = _north(m)
    return Waypoint4D(lat_deg=p.lat_deg, lon_deg=p.lon_deg, alt_amsl_m=p.alt_amsl_m, t_s=t_s)


def test_a_stored_plan_is_shifted_to_where_the_vehicle_is_on_it() -> None:
    wps = (_wp(0, 2000.0), _wp(100, 2010.0), _wp(200, 2020.0))
    plan = FlightPlan(operation_id=OperationId("sys1"), version=5, waypoints=wps)
    out = retimed_at(plan, _north(50, 53.0), 1950.0, version=6, reason="r", max_off_m=10.0)
    assert out is not None and out.version == 6
    assert [round(_north_m(w)) for w in out.waypoints] == [50, 100, 200]
    assert [round(w.t_s, 3) for w in out.waypoints] == [1950.0, 1955.0, 1965.0]
    # off the plan by more than the bound: not matched
    assert retimed_at(plan, _north(50, 70.0), 1950.0, version=6, reason="r", max_off_m=10.0) is None


def _plane_mission() -> list[_Item]:
    """PX4 plane: runway take-off heading for a position 300 m north, 600 and 900 m north."""
    lat, lon = _e7(HOME.lat_deg), _e7(HOME.lon_deg)
    return [
        _Item(command=22, x=lat + 3 * NORTH_100M_E7, y=lon, z=30.0, frame=6, seq=0),
        _Item(command=16, x=lat + 6 * NORTH_100M_E7, y=lon, z=30.0, frame=6, seq=1),
        _Item(command=16, x=lat + 9 * NORTH_100M_E7, y=lon, z=30.0, frame=6, seq=2),
    ]


async def test_a_restarted_service_retimes_the_stored_plan_before_any_download() -> None:
    usm, port, clock = _usm()
    port.mission = _plane_mission()
    plane = _Info(key=_Key(1), vehicle_kind=VehicleKind.FIXED_WING)
    usm.on_vehicle(plane)
    usm.on_status(_status(1000.0, total=3, home=HOME, position=HOME, landed=True))
    await usm.drain()
    flying = dict(total=3, home=HOME, armed=True, mode=FlightMode.MISSION, landed=False)
    for t, seq, m in ((1001.0, 0, 0.0), (1030.0, 1, 350.0)):
        clock.set(t)
        usm.on_status(_status(t, position=_north(m), seq=seq, **flying))  # type: ignore[arg-type]
        await usm.drain()
    stored = usm.airspace.by_sys_id(SysId(1))
    assert stored is not None
    at_600 = next(w.t_s for w in stored.plan.waypoints if abs(_north_m(w) - 600) < 1)
    # the next life: its clock 60 s behind; its mission download does not end
    usm, port, clock = _usm(clock_t=990.0)
    never = asyncio.get_running_loop().create_future()

    async def hangs(sys_id: SysId) -> list[_Item]:
        return await never  # type: ignore[no-any-return]

    port.download_mission = hangs  # type: ignore[method-assign]
    usm.attach_vehicles(port)
    usm.airspace.load([stored], [])
    usm.on_vehicle(plane)
    here = _north(450.0, stored.plan.waypoints[-1].alt_amsl_m)  # on the leg to 600 m north
    usm.on_status(_status(990.0, position=here, seq=1, **flying))  # type: ignore[arg-type]
    await asyncio.sleep(0)
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == stored.plan.version + 1
    assert op.plan.waypoints[0].t_s == 990.0 and round(_north_m(op.plan.waypoints[0])) == 450
    # where it is now on its plan is 150 m short of 600 m north, on this life's clock
    t_600 = next(w.t_s for w in op.plan.waypoints if abs(_north_m(w) - 600) < 1)
    assert 990.0 < t_600 < 1010.0 < at_600
    never.cancel()


async def test_a_plane_found_in_its_take_off_is_not_given_its_turning_heading() -> None:
    """The new life first heard the PX4 plane 9 m up in its take-off turn and filed the
    take-off from its home along the heading it had then (UAS_IN_CV 18.1 m): the take-off's
    run was not seen, its heading is not known."""
    usm, port, clock = _usm()
    port.mission = _plane_mission()
    usm.on_vehicle(_Info(key=_Key(1), vehicle_kind=VehicleKind.FIXED_WING))
    turning = dict(total=3, home=HOME, armed=True, mode=FlightMode.MISSION, landed=False)
    p = Position(lat_deg=HOME.lat_deg + 40 / 110_540.0, lon_deg=HOME.lon_deg, alt_amsl_m=41.3)
    usm.on_status(_turning(_status(1000.0, position=p, **turning)))  # type: ignore[arg-type]
    await usm.drain()
    clock.set(1000.5)
    usm.on_status(_turning(_status(1000.5, position=p, seq=0, **turning)))  # type: ignore[arg-type]
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    # on to the take-off position 300 m north: never out along the south-east heading
    assert max(abs(_east_m(w)) for w in op.plan.waypoints) < 5.0, op.plan.waypoints
    assert op.plan.waypoints[0].t_s == 1000.5


def _turning(s: VehicleStatus) -> VehicleStatus:
    return dataclasses.replace(s, heading_deg=120.0)  # south-east, half-way round its turn


async def test_a_plan_made_when_a_download_ends_starts_at_its_positions_time() -> None:
    """The ArduPlane found flying its final approach at 23 m/s by a restarted serve: its plan,
    made when the mission download ended, started from a position 1.3 s old, timed now
    (UAS_IN_CV 12.3 m). A plan from a position starts at that position's time."""
    usm, port, clock = _usm()
    port.mission = _plane_mission()
    release = asyncio.Event()
    plain = port.download_mission

    async def slow(sys_id: SysId) -> list[_Item]:
        await release.wait()
        return await plain(sys_id)

    port.download_mission = slow  # type: ignore[method-assign]
    usm.attach_vehicles(port)
    usm.on_vehicle(_Info(key=_Key(1), vehicle_kind=VehicleKind.FIXED_WING))
    flying = dict(total=3, home=HOME, armed=True, mode=FlightMode.MISSION, landed=False)
    status = _status(1000.0, position=_north(450.0), seq=1, **flying)  # type: ignore[arg-type]
    usm.on_status(dataclasses.replace(status, position_t_s=1000.0))
    await asyncio.sleep(0)
    clock.set(1001.3)  # no status since: the download ends 1.3 s after that position
    release.set()
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    first = op.plan.waypoints[0]
    assert round(_north_m(first)) == 450 and first.t_s == 1000.0
