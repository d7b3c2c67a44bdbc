"""The hub against ``sitl`` (the independent PX4/ArduPilot-like vehicle in ``sitl/``): discovery,
measurements, verified uploads (PX4 over UDP, ArduPilot over TCP with seq 0 = home), in-flight
re-planning through the current flag, mode commands, and a dead link that must fail an upload
inside its deadline. Simulation speed 5, loopback, ephemeral ports."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import pytest

import sitl
from adapters.mavlink import MavlinkConfig, MavlinkHub, plan_to_mission_items
from adapters.mavlink.mission import MissionItem, same_item
from gcs_utm.clock import ScaledClock
from gcs_utm.geo import haversine_m
from gcs_utm.model import (
    Autopilot,
    Command,
    CommandKind,
    FlightPlan,
    OperationId,
    Position,
    SysId,
    Waypoint4D,
)
from tests.mavlink.conftest import Sink

pytestmark = [pytest.mark.network, pytest.mark.timeout(60)]

SPEED = 5.0
HOME = (47.397742, 8.545594, 488.0)


@dataclass
class World:
    hub: MavlinkHub
    sink: Sink
    fleet: sitl.Fleet
    clock: ScaledClock

    @property
    def vehicle(self) -> sitl.Vehicle:
        return self.fleet.vehicles[0]


def _spec(**kw: Any) -> sitl.VehicleSpec:
    base: dict[str, Any] = {
        "instance": 0,
        "home_lat_deg": HOME[0],
        "home_lon_deg": HOME[1],
        "home_alt_amsl_m": HOME[2],
        "cruise_speed_mps": 5.0,
        "bind_port": 0,
    }
    base.update(kw)
    return sitl.VehicleSpec(**base)


@asynccontextmanager
async def world(
    spec_kw: dict[str, Any] | None = None,
    *,
    tcp: bool = False,
    speed: float = SPEED,
    **cfg_kw: Any,
) -> AsyncIterator[World]:
    clock = ScaledClock(speed=speed)
    # the vehicles' clock is built later (as in `gcs-utm run`) on the ground clock's anchor
    await asyncio.sleep(0.1)
    sim = sitl.SimTime(speed, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    sink = Sink()
    cfg = MavlinkConfig(
        links=() if tcp else ("udpin:127.0.0.1:0",),
        heartbeat_period_s=0.2,
        command_timeout_s=0.3,
        **cfg_kw,
    )
    async with MavlinkHub(cfg, clock, sink) as hub:
        spec_kw = dict(spec_kw or {})
        if not tcp:
            spec_kw["gcs_port"] = hub.local_port(next(iter(hub._links)))
        async with sitl.Fleet([_spec(**spec_kw)], sim) as fleet:
            if tcp:
                await hub.add_link(f"tcp:127.0.0.1:{fleet.vehicles[0].tcp_port}")
            w = World(hub=hub, sink=sink, fleet=fleet, clock=clock)
            await until(lambda: bool(sink.vehicles), 5.0, "vehicle not discovered")
            yield w


async def until(cond: Callable[[], bool], timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out: {what}")
        await asyncio.sleep(0.02)


def _plan(
    n: int, *, north0_deg: float = 0.0003, east_deg: float = 0.0, dt_s: float = 20.0
) -> FlightPlan:
    wps = tuple(
        Waypoint4D(
            lat_deg=HOME[0] + north0_deg + 0.0003 * i,
            lon_deg=HOME[1] + east_deg,
            alt_amsl_m=HOME[2] + 20.0 + i,
            t_s=dt_s * i,
        )
        for i in range(n)
    )
    return FlightPlan(operation_id=OperationId("op-sitl"), version=1, waypoints=wps)


def _assert_same(
    vehicle_items: tuple[Any, ...],
    sent: list[MissionItem],
    *,
    skip0: bool,
    autopilot: Autopilot = Autopilot.PX4,
) -> None:
    """The vehicle holds what was sent, by meaning (see mission.same_item): the vehicle's
    own frames and stored defaults (PX4 INT frames, ArduPilot NaN -> 0) are its rules."""
    assert len(vehicle_items) == len(sent)
    for got, want in zip(vehicle_items, sent, strict=True):
        if skip0 and want.seq == 0:
            continue
        back = MissionItem(
            seq=got.seq,
            command=got.command,
            frame=got.frame,
            autocontinue=got.autocontinue,
            param1=got.param1,
            param2=got.param2,
            param3=got.param3,
            param4=got.param4,
            x=got.x,
            y=got.y,
            z=got.z,
        )
        assert same_item(want, back, autopilot) == "", (want, got)


async def test_px4_discovery_measurements_and_verified_upload() -> None:
    async with world() as w:
        info = w.sink.vehicles[0]
        assert info.key.sys_id == 1 and info.autopilot is Autopilot.PX4
        assert info.key.address == f"127.0.0.1:{w.vehicle.local_port}"
        await until(lambda: len(w.sink.measurements) >= 3, 5.0, "no measurements")
        m = w.sink.measurements[-1]
        assert haversine_m(m.lat_deg, m.lon_deg, w.vehicle.lat_deg, w.vehicle.lon_deg) < 1.0
        assert m.alt_amsl_m == pytest.approx(HOME[2], abs=0.5)
        # capture time from SYSTEM_TIME on the shared simulated clock: not the arrival time
        assert -0.002 < m.receipt_t_s - m.capture_t_s < 0.05 * SPEED
        plan = _plan(6)
        res = await w.hub.upload_plan(SysId(1), plan, set_mission_mode=False)
        assert res.ok and res.verified and res.current_set, res
        sent = plan_to_mission_items(plan)
        _assert_same(w.vehicle.mission, sent, skip0=False)
        assert w.vehicle.counters["uploads_ok"] == 1
        assert w.vehicle.counters["handler_errors"] == 0
        assert w.hub.counters.bad_crc == 0 and w.hub.counters.handler_errors == 0


async def test_ardupilot_over_tcp_home_is_seq0() -> None:
    async with world({"autopilot": "ardupilot", "tcp_port": 0}, tcp=True) as w:
        st = w.hub.state(SysId(1))
        assert st.autopilot is Autopilot.ARDUPILOT
        # ArduPilot streams nothing until asked: the hub asks on discovery
        await until(lambda: bool(w.sink.measurements), 5.0, "ArduPilot streams not started")
        plan = _plan(4)
        # our seq 0 (plan start) differs from the vehicle's home: the readback must accept
        # that ArduPilot reports its own home there
        res = await w.hub.upload_plan(SysId(1), plan, set_mission_mode=False)
        assert res.ok and res.verified, res
        sent = plan_to_mission_items(plan, Autopilot.ARDUPILOT)
        assert sent[0].x == round(plan.waypoints[0].lat_deg * 1e7)  # home placeholder
        _assert_same(w.vehicle.mission, sent, skip0=True, autopilot=Autopilot.ARDUPILOT)
        assert w.vehicle.mission_current_seq >= 1


async def test_upload_in_flight_flies_the_new_first_item() -> None:
    first = _plan(4, north0_deg=0.0004)
    spec = {
        "mission": tuple(
            sitl.MissionItemSpec(lat_deg=p.lat_deg, lon_deg=p.lon_deg, alt_amsl_m=p.alt_amsl_m)
            for p in first.waypoints
        ),
        "auto_start_at_s": 0.0,
    }
    async with world(spec) as w:
        v = w.vehicle
        await until(lambda: v.mode == "MISSION" and v.mission_current_seq >= 1, 15.0, "not flying")
        # new plan to the east; its waypoint 1 is where we want to go now
        new = _plan(4, north0_deg=0.0, east_deg=0.0008)
        res = await w.hub.upload_plan(SysId(1), new, start_index=2)
        assert res.ok and res.verified and res.current_set and res.mode_set, res
        items = plan_to_mission_items(new, start_index=2)
        cur = next(i for i in items if i.current)
        # the flagged item may be a DO_CHANGE_SPEED, which the vehicle executes at once and
        # moves on to the navigation item after it: either is "flying the new first item"
        nav = next(i.seq for i in items if i.seq >= cur.seq and i.command == 16)
        assert cur.seq <= v.mission_current_seq <= nav
        target = new.waypoints[2]
        d0 = haversine_m(v.lat_deg, v.lon_deg, target.lat_deg, target.lon_deg)
        await asyncio.sleep(1.0)  # 5 s simulated at 5 m/s cruise
        d1 = haversine_m(v.lat_deg, v.lon_deg, target.lat_deg, target.lon_deg)
        assert d1 < d0 - 5.0, (d0, d1)
        assert v.mode == "MISSION"


async def test_commands_change_the_vehicle_mode() -> None:
    spec = {
        "mission": (
            sitl.MissionItemSpec(lat_deg=HOME[0] + 0.002, lon_deg=HOME[1], alt_amsl_m=HOME[2] + 30),
        ),
        "auto_start_at_s": 0.0,
    }
    async with world(spec) as w:
        v = w.vehicle
        await until(lambda: v.mode == "MISSION" and not v.landed, 10.0, "not flying")
        op = OperationId("op")
        for kind, mode in [
            (CommandKind.HOLD, "HOLD"),
            (CommandKind.RESUME, "MISSION"),
            (CommandKind.RTL, "RTL"),
            (CommandKind.LAND, "LAND"),
        ]:
            r = await w.hub.send_command(SysId(1), Command(kind=kind, operation_id=op))
            assert r.ok, (kind, r)
            assert v.mode == mode, kind
        # and the hub sees the new mode in the vehicle's next HEARTBEAT
        await until(
            lambda: w.sink.statuses[-1].mode.value.upper() == "LAND", 3.0, "LAND not reported"
        )
        target = Position(lat_deg=HOME[0] + 0.0005, lon_deg=HOME[1], alt_amsl_m=HOME[2] + 20)
        r = await w.hub.send_command(
            SysId(1), Command(kind=CommandKind.GOTO, operation_id=op, target=target)
        )
        assert r.result is not None  # the vehicle answered (accepted or refused while landing)


@pytest.mark.parametrize("how", ["fault_spec", "inject"])
async def test_link_loss_fails_upload_inside_its_deadline(how: str) -> None:
    # FaultSpec: the link dies 2 s (simulated) after start, i.e. after discovery
    faults = (sitl.FaultSpec(kind=sitl.FaultKind.LINK_LOSS, at_s=2.0, duration_s=None),)
    async with world({"faults": faults} if how == "fault_spec" else {}) as w:
        if how == "fault_spec":
            await until(lambda: w.vehicle.counters["dropped_link_loss"] > 0, 3.0, "no fault")
        else:
            w.vehicle.inject_fault(sitl.FaultKind.LINK_LOSS, duration_s=None)
        deadline = w.clock.now_s() + 1.5 * SPEED  # 1.5 s of wall time
        t0 = time.monotonic()
        res = await w.hub.upload_plan(SysId(1), _plan(5), deadline_t_s=deadline)
        took = time.monotonic() - t0
        assert not res.ok and not res.verified
        assert took < 1.5 + 0.3, took
        assert w.hub.counters.uploads_failed == 1
        assert w.vehicle.counters["dropped_link_loss"] > 0
        assert w.vehicle.mission == ()


async def test_link_loss_from_boot_upload_ends_inside_its_deadline() -> None:
    spec: dict[str, Any] = {
        "faults": (sitl.FaultSpec(kind=sitl.FaultKind.LINK_LOSS, at_s=0, duration_s=None),)
    }
    sim = sitl.SimTime(speed=SPEED)
    sink = Sink()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",))
    clock = ScaledClock(SPEED, start_utc_s=sim.start_utc_s, start_mono_s=sim.start_mono_s)
    async with MavlinkHub(cfg, clock, sink) as hub:
        spec["gcs_port"] = hub.local_port(next(iter(hub._links)))
        async with sitl.Fleet([_spec(**spec)], sim) as fleet:
            await asyncio.sleep(0.3)
            # sitl may get its boot burst out before the at_s=0 fault applies: the vehicle may
            # or may not be known; either way the upload must end unverified in time
            heard = bool(sink.vehicles)
            t0 = time.monotonic()
            res = await hub.upload_plan(
                SysId(1), _plan(3), deadline_t_s=clock.now_s() + 1.0 * SPEED
            )
            assert not res.ok and not res.verified
            assert time.monotonic() - t0 < 1.3
            assert ("deadline" in res.error) if heard else ("no vehicle" in res.error), res
            assert fleet.vehicles[0].counters["dropped_link_loss"] > 0
            assert fleet.vehicles[0].mission == ()


@pytest.mark.parametrize("speed", [1.0, 10.0])
async def test_telemetry_delay_is_the_link_latency_at_any_speed(speed: float) -> None:
    """receipt - capture (vehicle clock mapped to UTC through SYSTEM_TIME) is the link's
    one-way latency (sitl LATENCY, simulated seconds) plus loopback/loop time, whatever the
    speed-up: the vehicle and ground clocks are one clock, not two anchored apart."""
    latency_s = 0.2
    fault = sitl.FaultSpec(kind=sitl.FaultKind.LATENCY, at_s=0.0, duration_s=None, value=latency_s)
    async with world({"faults": (fault,)}, speed=speed) as w:
        await until(lambda: w.hub.state(SysId(1)).offset_from_system_time, 10.0, "no SYSTEM_TIME")
        n0 = len(w.sink.measurements)
        await until(lambda: len(w.sink.measurements) >= n0 + 10, 10.0, "no measurements")
        ms = w.sink.measurements[n0:]
        delays = [m.receipt_t_s - m.capture_t_s for m in ms]
        mean = sum(delays) / len(delays)
        # time_boot_ms is whole milliseconds (capture up to 1 ms late); loop time is wall time
        assert min(delays) > latency_s - 0.002, delays
        assert mean < latency_s + 0.025 * speed, delays


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
async def test_uploads_verify_through_20_percent_loss_each_way(autopilot: str) -> None:
    """With a fifth of the datagrams lost each way, uploads (upload, readback, set current)
    still verify, against both vehicle flavours: PX4 ignores the items we send ahead on a
    retry, ArduPilot NACKs them (INVALID_SEQUENCE) and answers a late repeat with ERROR; none
    of that may fail the transfer. How fast: `gcs-utm bench upload --loss 0.2`."""
    fault = sitl.FaultSpec(kind=sitl.FaultKind.PACKET_LOSS, at_s=0.0, duration_s=None, value=0.2)
    ap = Autopilot.ARDUPILOT if autopilot == "ardupilot" else Autopilot.PX4
    async with world({"autopilot": autopilot, "faults": (fault,), "seed": 3}) as w:
        plan = _plan(8)
        for _ in range(3):
            res = await w.hub.upload_plan(SysId(1), plan, set_mission_mode=False)
            assert res.ok and res.verified and res.current_set, res
            sent = plan_to_mission_items(plan, ap)
            _assert_same(w.vehicle.mission, sent, skip0=ap is Autopilot.ARDUPILOT, autopilot=ap)
        assert w.hub.counters.mission_retries > 0  # the loss was real
        assert w.hub.counters.uploads_failed == 0
