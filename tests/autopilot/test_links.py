"""A TCP link to real ArduCopter SITL survives the autopilot (issue 26 item 5): the hub
starts before SITL listens and connects when it does; SITL is killed (SIGKILL) and the
vehicle is reported lost (COMMUNICATION_FAILURE, link down) without a flood of send
warnings; SITL restarted in the same working directory is reconnected to, asked for its
streams again, and the vehicle is live again (positions, its reboot seen)."""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.app import Runtime
from gcs_utm.clock import RealClock
from gcs_utm.model import (
    FlightPlan,
    Operation,
    OperationId,
    SysId,
    Threat,
    ThreatKind,
    ThreatStatus,
    TrackId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.settings import Settings
from gcs_utm.store import Store
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import file_operations, serve_while, until
from tests.autopilot.pilot import PilotLink, mission_items
from tests.mavlink.conftest import Sink

SPEED = 5.0


# A single ArduPilot for about 10 s: runs beside the rest of the suite (load_tolerant,
# docs/testing.md).
@pytest.mark.load_tolerant
@pytest.mark.timeout(240)
async def test_hub_before_sitl_then_sitl_killed_and_restarted(
    ardupilot: Callable[..., SitlProcess], caplog: pytest.LogCaptureFixture
) -> None:
    sink = Sink()
    cfg = MavlinkConfig(
        links=("tcp:127.0.0.1:5760",),
        reconnect_min_s=0.2,
        reconnect_max_s=1.0,
        health_period_s=0.5,
    )
    caplog.set_level(logging.INFO)
    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        # serve starts although SITL is not listening yet: a clear line, then retries
        [ls] = hub.links()
        assert not ls.up and ls.failures >= 1
        assert any("not up" in r.getMessage() for r in caplog.records)
        await asyncio.sleep(1.0)
        p = ardupilot(instance=0, vehicle="copter", speed=SPEED)
        await until(lambda: hub.links()[0].up, 30.0, "no connection once SITL listens")
        await until(lambda: bool(sink.vehicles), 30.0, "ArduCopter not discovered")
        await until(lambda: bool(sink.measurements), 90.0, "no position from ArduCopter")
        assert sink.vehicles[0].key.sys_id == 1

        # SITL dies: the vehicle is lost, the link is down, nothing floods the log
        os.killpg(p.proc.pid, signal.SIGKILL)
        p.proc.wait(timeout=10.0)
        await until(lambda: not hub.links()[0].up, 10.0, "link not seen down")
        lost = [h for h in sink.hazards if h.kind is ThreatKind.COMMUNICATION_FAILURE]
        assert [h.sys_id for h in lost] == [1], lost
        await asyncio.sleep(3.0)  # heartbeats keep being due while it is down
        assert hub.links()[0].dropped_down >= 2

        # restarted in the same working directory: reconnected, streams asked again, live
        t_restart = time.time()
        n_before = len(sink.measurements)
        ardupilot(instance=0, vehicle="copter", speed=SPEED, workdir=p.workdir)
        await until(lambda: hub.links()[0].connects == 2, 30.0, "no reconnect")
        await until(
            lambda: any(m.receipt_t_s > t_restart for m in sink.measurements[n_before:]),
            90.0,
            "no position after the restart",
        )
        assert hub.links()[0].up
        st = hub.state(SysId(1))
        assert st.reboots >= 1  # time_boot_ms started again
        assert hub.counters.links_down == 1 and hub.counters.handler_errors == 0
        health = hub.health()[0]
        assert time.time() - health.last_heard_t_s < 5.0
    noisy = [r for r in caplog.records if "socket.send() raised exception" in r.getMessage()]
    assert not noisy
    warnings: list[Any] = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) < 20, [r.getMessage() for r in warnings]


@pytest.mark.timeout(240)
async def test_serve_keeps_an_operation_across_a_sitl_restart(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    """The same through ``serve`` (USM, tracking, store): it starts before SITL, the
    operation flying sysid 1 gets a COMMUNICATION_FAILURE threat when SITL dies, and its
    link health and track are live again after the restart."""
    db = tmp_path / "utm.sqlite"
    op = _operation()
    file_operations(db, op)
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(
            links=("tcp:127.0.0.1:5760",), reconnect_min_s=0.2, reconnect_max_s=1.0
        ),
    )

    def lost(rt: Runtime) -> bool:
        return any(
            t.kind is ThreatKind.COMMUNICATION_FAILURE and op.id in t.uas_ids
            for t in rt.usm.threats.values()
        )

    async def scenario(rt: Runtime) -> None:
        assert not rt.hub.links()[0].up  # serve starts without its link
        p = ardupilot(instance=0, vehicle="copter", speed=SPEED)
        await until(lambda: SysId(1) in rt.usm.health_by_sys_id(), 60.0, "not heard")
        await until(lambda: op.id in rt.tracks(), 90.0, "no track of the operation")
        # a link loss is an emergency in the air only (on the ground it is a pre-flight
        # finding): the pilot takes off in GUIDED on SERIAL1 and hovers
        pilot = await asyncio.to_thread(PilotLink, 0, "ardupilot", 5762)
        try:
            await asyncio.to_thread(pilot.wait_ready)
            await asyncio.to_thread(pilot.arm_and_start, 60.0, 20.0, auto=False)
            await until(lambda: rt.airspace.airborne(op.id), 30.0, "not airborne")
            os.killpg(p.proc.pid, signal.SIGKILL)
            p.proc.wait(timeout=10.0)
        finally:
            pilot.close()
        await until(lambda: lost(rt), 20.0, "no COMMUNICATION_FAILURE threat")
        t_restart = rt.clock.now_s()
        ardupilot(instance=0, vehicle="copter", speed=SPEED, workdir=p.workdir)
        await until(
            lambda: rt.usm.health_by_sys_id()[SysId(1)].last_heard_t_s > t_restart,
            60.0,
            "not heard after the restart",
        )
        await until(lambda: rt.tracks()[op.id].t_s > t_restart, 90.0, "track not live again")
        # positions flow again: the threat closes, and the link-loss geofence goes with it
        # (issue 31: it stayed open while positions flowed)
        await until(lambda: not lost(rt), 30.0, "COMMUNICATION_FAILURE stayed open")
        await until(
            lambda: not [g for g in rt.airspace.geofences() if g.id.startswith("em-")],
            10.0,
            "the link-loss geofence stayed",
        )

    await serve_while(settings, db, scenario, SPEED)
    with Store(db) as s:
        lost_rows = [t for t in s.load_threats() if t.kind is ThreatKind.COMMUNICATION_FAILURE]
        assert lost_rows and all(t.status is ThreatStatus.CLOSED for t in lost_rows)
        reasons = [
            a.detail["reason"]
            for a in s.load_audit()
            if a.actor == "usm" and a.action == "threat_closed"
        ]
        # restarted, the copter is on the ground: its link is back, or it landed/disarmed
        assert any(_cause_gone(str(r)) for r in reasons), reasons
        assert s.load_geofences(active_only=True) == []
        assert _conformance_kinds(s.load_threats()) == []


# One PX4 for about 10 s: runs beside the rest of the suite (load_tolerant, docs/testing.md).
@pytest.mark.load_tolerant
@pytest.mark.timeout(240)
async def test_serve_closes_the_link_loss_of_a_restarted_px4(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    """A PX4 (SIH) killed and started again: the operation flying sysid 1 gets a
    COMMUNICATION_FAILURE and EM's temporary geofence; once PX4's positions flow again the
    threat closes (it stayed open while they flowed, issue 31) and the geofence goes."""
    db = tmp_path / "utm.sqlite"
    lat, lon, ground_m = PX4_DEFAULT_HOME
    op = _operation((lat, lon, ground_m))
    file_operations(db, op)
    settings = dataclasses.replace(
        Settings(), mavlink=MavlinkConfig(links=("udpin:127.0.0.1:14550",))
    )

    def lost(rt: Runtime) -> bool:
        return any(t.kind is ThreatKind.COMMUNICATION_FAILURE for t in rt.usm.threats.values())

    def fenced(rt: Runtime) -> bool:
        return any(g.id.startswith("em-") for g in rt.airspace.geofences())

    async def scenario(rt: Runtime) -> None:
        p = px4(instance=0, speed=SPEED)
        await until(lambda: TrackId(op.id) in rt.tracks(), 90.0, "no track of the operation")
        # in the air (a grounded vehicle's link loss is a pre-flight finding): the pilot
        # uploads a take-off and a waypoint on the API link and starts the mission
        pilot = await asyncio.to_thread(PilotLink, 0)
        try:
            await asyncio.to_thread(pilot.wait_ready)
            assert pilot.home is not None
            alt_m = pilot.home[2] + 20.0
            items = mission_items(1, (lat, lon), [(lat, lon, alt_m), (lat + 0.001, lon, alt_m)])
            await asyncio.to_thread(pilot.upload, items)
            await asyncio.to_thread(pilot.arm_and_start)
            await until(lambda: rt.airspace.airborne(op.id), 60.0, "not airborne")
            os.killpg(p.proc.pid, signal.SIGKILL)
            p.proc.wait(timeout=10.0)
        finally:
            pilot.close()
        await until(lambda: lost(rt) and fenced(rt), 30.0, "no link loss and fence")
        t_restart = rt.clock.now_s()
        px4(instance=0, speed=SPEED)
        await until(
            lambda: rt.usm.health_by_sys_id()[SysId(1)].last_heard_t_s > t_restart,
            90.0,
            "not heard after the restart",
        )
        await until(lambda: not lost(rt), 30.0, "COMMUNICATION_FAILURE stayed open")
        await until(lambda: not fenced(rt), 10.0, "the link-loss geofence stayed")

    await serve_while(settings, db, scenario, SPEED)
    with Store(db) as s:
        rows = [t for t in s.load_threats() if t.kind is ThreatKind.COMMUNICATION_FAILURE]
        assert rows and all(t.status is ThreatStatus.CLOSED for t in rows)
        closed_by = [t.message for t in rows]
        assert all(_cause_gone(m) for m in closed_by), closed_by
        # the silent, dead-reckoned track raised no conformance alarm around the drop
        assert _conformance_kinds(s.load_threats()) == []


def _conformance_kinds(threats: list[Threat]) -> list[ThreatKind]:
    """Conformance threats among ``threats`` (a silent track is no conformance evidence)."""
    return [t.kind for t in threats if t.kind in (ThreatKind.UAS_IN_CV, ThreatKind.UAS_OUT_OV)]


def _cause_gone(reason: str) -> bool:
    """A link loss's closing reason: positions back, or the vehicle back on the ground."""
    return any(k in reason for k in ("flow again", "on the ground", "landed"))


def _operation(home: tuple[float, float, float] | None = None) -> Operation:
    lat, lon, ground_m = home or ARDUPILOT_DEFAULT_HOME[:3]
    t0 = time.time()
    plan = FlightPlan(
        operation_id=OperationId("AP1"),
        version=1,
        waypoints=(
            Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=ground_m + 20.0, t_s=t0),
            Waypoint4D(lat_deg=lat + 0.001, lon_deg=lon, alt_amsl_m=ground_m + 20.0, t_s=t0 + 3600),
        ),
    )
    return Operation(
        id=plan.operation_id,
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=plan,
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=5.0,
        operational_volume_m=50.0,
    )
