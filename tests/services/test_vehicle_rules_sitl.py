"""Issue 31's vehicle rules for the built-in vehicles (``sitl/``), as ``tests/autopilot``
checks them against real PX4 (``test_do_jump.py``, ``test_px4_arming.py``): the ground
service's receive stack of ``test_vehicle_time.py`` (hub, USM, tracking) over loopback UDP
with a PX4-personality ``sitl`` vehicle.

- a mission with a DO_JUMP loop is filed as the vehicle flies it, and its upload sets the
  current item with one MISSION_SET_CURRENT;
- a disarmed vehicle's plan is timed from its take-off, not from its filing;
- the operation's home follows the vehicle's: re-filed when DO_SET_HOME moves it on the
  ground, and at arming (the vehicle takes its home where it arms: here after landing 40 m
  from where it took off).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest

import sitl
from gcs_utm.clock import ScaledClock
from gcs_utm.geo import haversine_m
from gcs_utm.model import SysId
from sitl.vehicle import Vehicle
from tests.autopilot.autopilots import PX4_DEFAULT_HOME
from tests.autopilot.test_do_jump import REL_ALT_M, A, B, C, _mission, _set_current
from tests.autopilot.test_vehicle_time import Stack, px4_mission, stack, until

pytestmark = [pytest.mark.network, pytest.mark.timeout(90)]

SPEED = 10.0
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
SYS = SysId(1)
DO_SET_HOME, NAV_TAKEOFF, DO_REPOSITION, NAV_LAND = 179, 22, 192, 21


@asynccontextmanager
async def _rig(**spec: object) -> AsyncIterator[tuple[Stack, Vehicle]]:
    clock = ScaledClock(SPEED)
    sim = sitl.SimTime(SPEED, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    async with stack("udpin:127.0.0.1:0", clock, GROUND_M) as s:
        vs = sitl.VehicleSpec(
            instance=0,
            home_lat_deg=LAT0,
            home_lon_deg=LON0,
            home_alt_amsl_m=GROUND_M,
            gcs_port=s.hub.local_port(next(iter(s.hub._links))),
            bind_port=0,
            **spec,  # type: ignore[arg-type]
        )
        async with sitl.Fleet([vs], sim) as fleet:
            await until(s.hub.vehicles, 20.0, "sitl vehicle not discovered")
            await until(lambda: s.usm.vehicle_ops.counters["downloads"] >= 1, 20.0, "no download")
            await s.usm.drain()
            yield s, fleet.vehicles[0]


async def test_a_do_jump_loop_is_filed_as_the_sitl_vehicle_flies_it() -> None:
    """As test_do_jump.py on real PX4: A and B three times (repeat count 2), then C, in time
    order; one MISSION_SET_CURRENT for the upload (tests/sitl/test_ground_rules.py checks
    that the vehicle flies that order)."""
    async with _rig() as (s, _v):
        sent: list[int] = []
        s.hub.raw_tap = lambda _link, frame, _t: sent.extend(_set_current(frame))
        res = await s.hub.upload_items(SYS, _mission(), set_mission_mode=False)
        s.hub.raw_tap = None
        assert res.ok and res.verified, res
        assert 1 <= len(sent) <= 2, sent  # a second only after the 0.5 s command timeout
        await until(s.op, 30.0, "no operation filed from the mission with a loop")
        op = s.op()
        assert op is not None
    wps = op.plan.waypoints

    def visits(at: tuple[float, float]) -> list[int]:
        return [i for i, w in enumerate(wps) if haversine_m(w.lat_deg, w.lon_deg, *at) < 2.0]

    a, b, c = visits(A), visits(B), visits(C)
    assert (len(a), len(b), len(c)) == (3, 3, 1), op.plan
    assert sorted(a + b + c) == [a[0], b[0], a[1], b[1], a[2], b[2], c[0]]
    assert all(x.t_s <= y.t_s for x, y in itertools.pairwise(wps)), op.plan
    assert op.home is not None
    for i in a + b + c:
        assert math.isclose(wps[i].alt_amsl_m, op.home.alt_amsl_m + REL_ALT_M, abs_tol=0.05)


async def test_a_disarmed_sitl_vehicles_plan_is_timed_from_its_take_off() -> None:
    """As test_px4_arming.py: filed on the ground, left there 20 simulated seconds, then armed
    and started by its pilot: the plan is re-timed from the take-off."""
    async with _rig() as (s, v):
        res = await s.hub.upload_items(SYS, px4_mission(25.0), set_mission_mode=False)
        assert res.ok and res.verified, res
        await until(s.op, 30.0, "no operation filed from the mission")
        filed = s.op()
        assert filed is not None
        assert v.mode != "MISSION" and not v.armed  # the upload set no mode on the ground
        t_filed = s.clock.now_s()
        await until(lambda: s.clock.now_s() > t_filed + 20.0, 10.0, "clock")
        t_arm = s.clock.now_s()
        assert v.arm() == 0 and v.commands.request_mode("MISSION") == 0  # the pilot
        await until(
            lambda: (
                (op := s.op()) is not None
                and op.plan.version > filed.plan.version
                and op.plan.start_t_s >= t_arm - 1.0
            ),
            10.0,
            "the plan was not re-timed from the take-off",
        )


async def test_the_home_follows_the_sitl_vehicle_on_the_ground_and_at_arming() -> None:
    mission = (
        sitl.MissionItemSpec(lat_deg=LAT0 + 0.002, lon_deg=LON0, alt_amsl_m=GROUND_M + 30.0),
    )
    async with _rig(mission=mission) as (s, v):
        await until(lambda: (op := s.op()) is not None and op.home is not None, 20.0, "no op")
        # DO_SET_HOME on the ground, 4 m higher: the operation is re-filed with that home
        set_home = (0.0, 0.0, 0.0, math.nan, LAT0, LON0, GROUND_M + 4.0)
        assert (await s.hub.command_long(SYS, DO_SET_HOME, set_home)).ok
        await until(
            lambda: (
                (op := s.op()) is not None
                and op.home is not None
                and math.isclose(op.home.alt_amsl_m, GROUND_M + 4.0, abs_tol=0.1)
            ),
            10.0,
            "the operation did not take the home DO_SET_HOME moved",
        )
        # DO_SET_HOME to where it stands (an automatic home again), a hop 40 m north and a
        # landing there; armed again, it takes its home there, and so does the operation
        assert (await s.hub.command_long(SYS, DO_SET_HOME, (1.0,) + (0.0,) * 6)).ok
        assert v.arm() == 0
        up = (0.0, 0.0, 0.0, math.nan, math.nan, math.nan, GROUND_M + 10.0)
        assert (await s.hub.command_long(SYS, NAV_TAKEOFF, up)).ok
        await until(lambda: v.alt_amsl_m > GROUND_M + 9.0, 20.0, "no take-off")
        north = LAT0 + 40.0 / 111_320.0
        hop = (-1.0, 1.0, 0.0, math.nan, north, LON0, GROUND_M + 10.0)
        assert (await s.hub.command_long(SYS, DO_REPOSITION, hop)).ok
        await until(lambda: abs(v.lat_deg - north) * 111_320 < 1.0, 20.0, "no hop")
        assert (await s.hub.command_long(SYS, NAV_LAND, (0.0,) * 7)).ok
        await until(lambda: not v.armed, 20.0, "not landed and disarmed")
        op = s.op()
        assert op is not None and op.home is not None
        assert haversine_m(op.home.lat_deg, op.home.lon_deg, LAT0, LON0) < 2.0
        assert v.arm() == 0
        await until(
            lambda: (
                (op := s.op()) is not None
                and op.home is not None
                and haversine_m(op.home.lat_deg, op.home.lon_deg, north, LON0) < 2.0
            ),
            10.0,
            "the operation did not take the home at arming",
        )
