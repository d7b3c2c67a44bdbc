"""Operations from vehicles, end to end over loopback UDP: a ``sitl`` vehicle that has a
mission and no registered operation connects; the USM downloads its mission through the real
MAVLink hub and files an operation with the mission's waypoints and 4D times from its
DO_CHANGE_SPEED items (ArduPilot: seq 0 is home and is not a waypoint)."""

from __future__ import annotations

import asyncio
import time

import pytest

import sitl
from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import ScaledClock
from gcs_utm.geo import haversine_m
from gcs_utm.model import Operation, SysId
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm

pytestmark = [pytest.mark.network, pytest.mark.timeout(60)]

HOME = (47.397742, 8.545594, 488.0)
MISSION = (
    sitl.MissionItemSpec(
        lat_deg=HOME[0] + 0.0005, lon_deg=HOME[1], alt_amsl_m=HOME[2] + 30.0, speed_mps=4.0
    ),
    sitl.MissionItemSpec(
        lat_deg=HOME[0] + 0.0015, lon_deg=HOME[1], alt_amsl_m=HOME[2] + 30.0, speed_mps=8.0
    ),
    sitl.MissionItemSpec(
        lat_deg=HOME[0] + 0.0015, lon_deg=HOME[1] + 0.001, alt_amsl_m=HOME[2] + 40
    ),
)


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
async def test_connecting_vehicle_with_a_mission_gets_an_operation(autopilot: str) -> None:
    clock = ScaledClock(5.0)
    sim = sitl.SimTime(5.0, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    airspace = Airspace()
    usm = Usm(airspace, clock)
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2)
    async with MavlinkHub(cfg, clock, usm) as hub:
        usm.attach_vehicles(hub)
        spec = sitl.VehicleSpec(
            instance=0,
            autopilot=autopilot,
            home_lat_deg=HOME[0],
            home_lon_deg=HOME[1],
            home_alt_amsl_m=HOME[2],
            cruise_speed_mps=5.0,
            mission=MISSION,
            gcs_port=hub.local_port(next(iter(hub._links))),
            bind_port=0,
        )
        async with sitl.Fleet([spec], sim):
            end = time.monotonic() + 15.0
            op: Operation | None = None
            while (op := airspace.by_sys_id(SysId(1))) is None:
                assert time.monotonic() < end, "no operation filed from the vehicle's mission"
                await asyncio.sleep(0.05)
            await usm.drain()
    assert op.id == "sys1" and op.sys_id == 1
    # the plan starts where the vehicle is when its position is known at filing (at home,
    # on the ground; ArduPilot's mission can come first), then the mission
    wps = op.plan.waypoints
    if haversine_m(wps[0].lat_deg, wps[0].lon_deg, *HOME[:2]) < 5:
        wps = wps[1:]
    assert op.home is not None and op.home.alt_amsl_m == pytest.approx(HOME[2], abs=0.5)
    assert [(round(w.lat_deg, 6), round(w.lon_deg, 6)) for w in wps] == [
        (round(m.lat_deg, 6), round(m.lon_deg, 6)) for m in MISSION
    ]
    assert [w.alt_amsl_m for w in wps] == pytest.approx([m.alt_amsl_m for m in MISSION], abs=0.01)
    # 4D times: the leg to waypoint k at the speed of the DO_CHANGE_SPEED just before it (the
    # vehicle runs it on reaching k-1), kept until the next one: 8 m/s to 1 and to 2
    for k, speed in ((1, 8.0), (2, 8.0)):
        a, b = wps[k - 1], wps[k]
        dist = haversine_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg)
        dist = (dist**2 + (b.alt_amsl_m - a.alt_amsl_m) ** 2) ** 0.5
        assert b.t_s - a.t_s == pytest.approx(dist / speed, rel=0.01), k
    assert op.plan.waypoints[0].t_s == pytest.approx(clock.now_s(), abs=20.0)  # filed now


async def test_a_mission_before_the_fix_is_filed_whole_with_the_home_after_it() -> None:
    """A PX4 acquiring GNSS for 3 s after boot sends HOME_POSITION 2 m low before its fix (as
    PX4 SIH does): the home is the one after the fix, and the mission is filed whole once the
    fix comes, never before (issue 31.3)."""
    clock = ScaledClock(5.0)
    sim = sitl.SimTime(5.0, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    airspace = Airspace()
    usm = Usm(airspace, clock)
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2)
    async with MavlinkHub(cfg, clock, usm) as hub:
        usm.attach_vehicles(hub)
        spec = sitl.VehicleSpec(
            instance=0,
            home_lat_deg=HOME[0],
            home_lon_deg=HOME[1],
            home_alt_amsl_m=HOME[2],
            mission=MISSION,
            gcs_port=hub.local_port(next(iter(hub._links))),
            bind_port=0,
            gnss_fix_after_s=3.0,
        )
        async with sitl.Fleet([spec], sim):
            end = time.monotonic() + 15.0
            while (op := airspace.by_sys_id(SysId(1))) is None or op.home is None:
                assert time.monotonic() < end, "no operation with a home from the vehicle"
                s = usm.statuses_by_sys_id().get(SysId(1))
                assert s is None or s.home is None or (s.gnss_fix_type or 0) >= 3
                if op is not None:  # filed: never before the fix, always whole
                    assert usm.flight[(SysId(1), s.vehicle)].had_fix  # type: ignore[union-attr]
                    assert len(op.plan.waypoints) >= len(MISSION)
                await asyncio.sleep(0.02)
            await usm.drain()
    assert op.home.alt_amsl_m == pytest.approx(HOME[2], abs=0.01)  # not the one 2 m low
    assert len(op.plan.waypoints) >= len(MISSION)  # every mission waypoint, not the last only
