"""One conformance scenario for missions and commands, run against ``sitl/`` (PX4 and ArduPilot
personalities) and the real autopilots (PX4 v1.15.2 SIH quad, ArduCopter and ArduPlane 4.6
SITL), all through the project's own ``MavlinkHub``:

1. arm and take off (PX4: NAV_TAKEOFF to an AMSL altitude; ArduCopter: GUIDED + NAV_TAKEOFF
   above home; ArduPlane: an AUTO mission that starts with NAV_TAKEOFF);
2. upload a timed plan in flight (DO_CHANGE_SPEED before each leg): the vehicle accepts it,
   its copy reads back equal by meaning, MISSION_SET_CURRENT is confirmed by MISSION_CURRENT,
   HEARTBEAT shows mission mode, and MISSION_CURRENT advances (the vehicle flies it);
3. HOLD is acknowledged and holds altitude (ArduCopter BRAKE: LOITER would descend without
   RC throttle; ArduPlane LOITER circles at altitude);
4. RTL is acknowledged and shown; LAND is acknowledged and the vehicle descends (ArduPlane:
   DO_LAND_START fails without a landing sequence, the fallback landing mission flies).

Ground and boot rules (issue 31), before step 1 and during step 2: DO_SET_HOME on the ground
moves home (HOME_POSITION shows it 3 m higher) and DO_SET_HOME "here" takes it back; NAV_TAKEOFF
while disarmed is taken by PX4 and refused by ArduCopter (FAILED); a reboot while armed is
refused (PX4 DENIED, ArduPilot FAILED) and the vehicle flies on.

The ``sitl`` cases need nothing; the real ones need ``../shared`` and a private network
namespace (``bash tests/netns.sh .venv/bin/python -m pytest tests/autopilot/test_conformance.py``)
and skip, saying why, without them.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import pytest

import sitl
from adapters.mavlink import MavlinkConfig, MavlinkHub, UploadResult
from adapters.mavlink.mission import MissionItem
from gcs_utm.clock import ScaledClock
from gcs_utm.messages import FlightMode
from gcs_utm.model import (
    Autopilot,
    Command,
    CommandKind,
    FlightPlan,
    OperationId,
    SysId,
    VehicleKind,
    Waypoint4D,
)
from tests.autopilot.autopilots import (
    ARDUPILOT_DEFAULT_HOME,
    PX4_DEFAULT_HOME,
    SitlProcess,
    wait_tcp_listening,
)
from tests.mavlink.conftest import Sink

pytestmark = [pytest.mark.network, pytest.mark.timeout(240)]

MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_HOME = 179
MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN = 246
MAV_RESULT_DENIED, MAV_RESULT_FAILED = 2, 4
SYS = SysId(1)
_NAN = math.nan


@dataclass(frozen=True)
class Case:
    name: str
    autopilot: Autopilot
    kind: VehicleKind
    real: bool
    speed: float
    home: tuple[float, float, float]  # lat, lon, ground AMSL m


CASES = [
    Case("sitl-px4", Autopilot.PX4, VehicleKind.MULTIROTOR, False, 5.0, PX4_DEFAULT_HOME),
    Case(
        "sitl-ardupilot",
        Autopilot.ARDUPILOT,
        VehicleKind.MULTIROTOR,
        False,
        5.0,
        ARDUPILOT_DEFAULT_HOME[:3],
    ),
    Case(
        "sitl-arduplane",
        Autopilot.ARDUPILOT,
        VehicleKind.FIXED_WING,
        False,
        8.0,
        ARDUPILOT_DEFAULT_HOME[:3],
    ),
    Case("px4-quad", Autopilot.PX4, VehicleKind.MULTIROTOR, True, 5.0, PX4_DEFAULT_HOME),
    Case(
        "arducopter",
        Autopilot.ARDUPILOT,
        VehicleKind.MULTIROTOR,
        True,
        5.0,
        ARDUPILOT_DEFAULT_HOME[:3],
    ),
    Case(
        "arduplane",
        Autopilot.ARDUPILOT,
        VehicleKind.FIXED_WING,
        True,
        8.0,
        ARDUPILOT_DEFAULT_HOME[:3],
    ),
]


def case_params(cases: list[Case]) -> list[Any]:
    """``cases`` as pytest parameters: those on a real PX4 carry the ``px4`` mark, which the
    fixture-based marking in tests/conftest.py cannot see (``request.getfixturevalue``)."""
    return [
        pytest.param(
            c, id=c.name, marks=[pytest.mark.px4] if c.real and c.autopilot is Autopilot.PX4 else []
        )
        for c in cases
    ]


@dataclass
class Rig:
    case: Case
    hub: MavlinkHub
    sink: Sink

    @property
    def alt_m(self) -> float:
        pos = self.hub.state(SYS).last_position
        return _NAN if pos is None else pos.alt_amsl_m

    @property
    def height_m(self) -> float:
        return self.alt_m - self.case.home[2]


async def until(cond: Callable[[], bool], timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout_s} s: {what}")
        await asyncio.sleep(0.05)


def _config(link: str) -> MavlinkConfig:
    return MavlinkConfig(links=(link,), heartbeat_period_s=0.5, ardupilot_stream_hz=10.0)


@asynccontextmanager
async def _sitl_rig(case: Case) -> AsyncIterator[Rig]:
    clock = ScaledClock(speed=case.speed)
    sim = sitl.SimTime(case.speed, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    sink = Sink()
    ap = case.autopilot is Autopilot.ARDUPILOT
    spec: dict[str, Any] = {
        "instance": 0,
        "autopilot": "ardupilot" if ap else "px4",
        "kind": "fixed_wing" if case.kind is VehicleKind.FIXED_WING else "multirotor",
        "home_lat_deg": case.home[0],
        "home_lon_deg": case.home[1],
        "home_alt_amsl_m": case.home[2],
        "bind_port": None if ap else 0,
        "tcp_port": 0 if ap else None,
    }
    async with MavlinkHub(_config("udpin:127.0.0.1:0"), clock, sink) as hub:
        spec["gcs_port"] = hub.local_port(next(iter(hub._links)))
        async with sitl.Fleet([sitl.VehicleSpec(**spec)], sim) as fleet:
            if ap:
                await hub.add_link(f"tcp:127.0.0.1:{fleet.vehicles[0].tcp_port}")
            yield Rig(case, hub, sink)


@asynccontextmanager
async def _real_rig(case: Case, start: Callable[..., SitlProcess]) -> AsyncIterator[Rig]:
    clock = ScaledClock(speed=case.speed)
    sink = Sink()
    if case.autopilot is Autopilot.PX4:
        link = "udpin:127.0.0.1:14550"
        start(instance=0, airframe="quad", speed=case.speed)
    else:
        vehicle = "plane" if case.kind is VehicleKind.FIXED_WING else "copter"
        start(instance=0, vehicle=vehicle, speed=case.speed)
        await asyncio.to_thread(wait_tcp_listening, 5760)
        link = "tcp:127.0.0.1:5760"
    async with MavlinkHub(_config(link), clock, sink) as hub:
        yield Rig(case, hub, sink)


def _plan(case: Case, *, leg_m: float, speed_mps: float, height_m: float) -> FlightPlan:
    """Four waypoints north of home, ``leg_m`` apart, timed at ``speed_mps``."""
    lat0, lon0, ground = case.home
    dlat = leg_m / 111_320.0
    wps = tuple(
        Waypoint4D(
            lat_deg=lat0 + dlat * (i + 1),
            lon_deg=lon0,
            alt_amsl_m=ground + height_m + i,
            t_s=i * leg_m / speed_mps,
        )
        for i in range(4)
    )
    return FlightPlan(operation_id=OperationId(f"conf-{case.name}"), version=1, waypoints=wps)


async def _arm(rig: Rig) -> None:
    """Arm, retrying while the autopilot refuses (no position estimate yet)."""
    end = time.monotonic() + 90.0
    while True:
        res = await rig.hub.command_long(SYS, MAV_CMD_COMPONENT_ARM_DISARM, (1.0,) + (0.0,) * 6)
        if res.ok:
            return
        assert time.monotonic() < end, f"not armable: {res.error}"
        await asyncio.sleep(1.0)


async def _take_off(rig: Rig, height_m: float) -> None:
    case, hub = rig.case, rig.hub
    st = hub.state(SYS)
    await until(lambda: st.last_position is not None, 90.0, "no position")
    if case.kind is VehicleKind.FIXED_WING:
        lat, lon, ground = case.home
        items = [
            MissionItem(seq=0, command=16, x=round(lat * 1e7), y=round(lon * 1e7), z=ground),
            MissionItem(seq=1, command=22, frame=3, current=1, param1=15.0, z=height_m),
            MissionItem(
                seq=2,
                command=16,
                frame=3,
                x=round((lat + 0.01) * 1e7),
                y=round(lon * 1e7),
                z=height_m,
            ),
        ]
        up = await hub.upload_items(SYS, items)
        assert up.ok and not up.mode_set, up  # disarmed: the mode stays the pilot's
        assert (await hub.send_mode(SYS, FlightMode.MISSION)).ok  # the pilot's AUTO
        await _arm(rig)
    else:
        alt = height_m if case.autopilot is Autopilot.ARDUPILOT else case.home[2] + height_m
        # disarmed: PX4 takes NAV_TAKEOFF (AUTO.TAKEOFF, it takes off once armed),
        # ArduCopter answers FAILED (do_user_takeoff needs the motors armed)
        takeoff = (0.0, 0.0, 0.0, _NAN, _NAN, _NAN, alt)
        res = await hub.command_long(SYS, MAV_CMD_NAV_TAKEOFF, takeoff)
        if case.autopilot is Autopilot.ARDUPILOT:
            assert not res.ok and res.result == MAV_RESULT_FAILED, res
            assert (await hub.send_mode(SYS, FlightMode.GUIDED)).ok
        else:
            assert res.ok, res
        await _arm(rig)
        res = await hub.command_long(
            SYS, MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, _NAN, _NAN, _NAN, alt)
        )
        assert res.ok, res
    await until(lambda: rig.height_m > 0.7 * height_m, 60.0, f"climb to {height_m} m")


async def _holds_altitude(rig: Rig, sim_s: float, tol_m: float) -> tuple[float, float]:
    await asyncio.sleep(1.0 / rig.case.speed * 3.0)  # let the mode settle (3 s simulated)
    a0 = rig.alt_m
    await asyncio.sleep(sim_s / rig.case.speed)
    a1 = rig.alt_m
    assert abs(a1 - a0) < tol_m, f"altitude {a0:.1f} -> {a1:.1f} m in hold"
    return a0, a1


async def _home_moves_on_the_ground(rig: Rig) -> None:
    """DO_SET_HOME 3 m above the ground is shown in HOME_POSITION; "here" takes it back."""
    st = rig.hub.state(SYS)
    lat, lon, ground = rig.case.home
    await until(lambda: st.home is not None, 90.0, "no HOME_POSITION (no fix)")
    up = (0.0, 0.0, 0.0, _NAN, lat, lon, ground + 3.0)
    assert (await rig.hub.command_long(SYS, MAV_CMD_DO_SET_HOME, up)).ok
    await until(
        lambda: st.home is not None and abs(st.home.alt_amsl_m - ground - 3.0) < 0.5,
        10.0,
        "HOME_POSITION does not show the home DO_SET_HOME set",
    )
    assert (await rig.hub.command_long(SYS, MAV_CMD_DO_SET_HOME, (1.0,) + (0.0,) * 6)).ok
    await until(
        lambda: st.home is not None and abs(st.home.alt_amsl_m - ground) < 1.5,
        10.0,
        "DO_SET_HOME here did not take home back to the vehicle",
    )


async def _no_reboot_in_flight(rig: Rig) -> None:
    refused = MAV_RESULT_DENIED if rig.case.autopilot is Autopilot.PX4 else MAV_RESULT_FAILED
    res = await rig.hub.command_long(SYS, MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, (1.0,) + (0.0,) * 6)
    assert not res.ok and res.result == refused, res
    assert rig.hub.state(SYS).reboots == 0


def _check_upload(res: UploadResult) -> None:
    assert res.ok and res.verified and res.current_set and res.mode_set, res
    assert res.failure is None and res.current_seq is not None


@pytest.mark.parametrize("case", case_params(CASES))
async def test_mission_and_commands(case: Case, request: pytest.FixtureRequest) -> None:
    if case.real:
        start = request.getfixturevalue("px4" if case.autopilot is Autopilot.PX4 else "ardupilot")
        rig_cm = _real_rig(case, start)
    else:
        rig_cm = _sitl_rig(case)
    plane = case.kind is VehicleKind.FIXED_WING
    height_m = 50.0 if plane else 20.0
    async with rig_cm as rig:
        hub = rig.hub
        await until(lambda: bool(rig.sink.vehicles), 30.0, "vehicle not discovered")
        st = hub.state(SYS)
        assert st.autopilot is case.autopilot and st.kind is case.kind
        plan = _plan(
            case,
            leg_m=300.0 if plane else 40.0,
            speed_mps=20.0 if plane else 5.0,
            height_m=height_m,
        )
        if not plane:
            # 1. on the ground, at discovery (ArduPilot refuses uploads with NO_SPACE for a
            # moment after boot: the retry covers it)
            res = await hub.upload_plan(SYS, plan, set_mission_mode=False)
            assert res.ok and res.verified and res.current_set, res
        await _home_moves_on_the_ground(rig)
        await _take_off(rig, height_m)

        # 2. a timed plan with speed items, uploaded in flight
        # start at waypoint 1: its DO_CHANGE_SPEED is the flagged item (PX4 starts there,
        # ArduPilot at the waypoint after it)
        res = await hub.upload_plan(SYS, plan, start_index=1)
        _check_upload(res)
        assert res.current_seq is not None
        assert st.mode is FlightMode.MISSION
        first = res.current_seq
        await until(
            lambda: (st.mission_seq or 0) > first + 1, 60.0, f"MISSION_CURRENT past {first}"
        )
        await _no_reboot_in_flight(rig)

        # 3. hold keeps the altitude
        r = await hub.send_command(
            SYS, Command(kind=CommandKind.HOLD, operation_id=plan.operation_id)
        )
        assert r.ok, r
        await until(lambda: st.mode is FlightMode.HOLD, 5.0, "HOLD not shown")
        await _holds_altitude(rig, 10.0, 8.0 if plane else 1.5)

        # 4. RTL shown; LAND descends
        r = await hub.send_command(
            SYS, Command(kind=CommandKind.RTL, operation_id=plan.operation_id)
        )
        assert r.ok, r
        await until(lambda: st.mode is FlightMode.RTL, 5.0, "RTL not shown")
        a0 = rig.alt_m
        r = await hub.send_command(
            SYS, Command(kind=CommandKind.LAND, operation_id=plan.operation_id)
        )
        assert r.ok, r
        landing_mode = FlightMode.MISSION if plane else FlightMode.LAND
        await until(lambda: st.mode is landing_mode, 5.0, f"{landing_mode.value} not shown")
        await until(lambda: rig.alt_m < a0 - 5.0, 60.0, "no descent after LAND")
