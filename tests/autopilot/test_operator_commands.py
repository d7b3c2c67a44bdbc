"""Operator commands reach real autopilots (PX4 v1.15.2 SIH quad, ArduCopter 4.6 SITL) through
the USM's one entry point and the project's ``MavlinkHub``: refused while the vehicle is
disarmed on the ground; in flight, an operator ``hold``, ``resume``, ``rtl`` then ``land`` are
acknowledged and confirmed by the mode the autopilot's HEARTBEAT reports (PX4 AUTO.LOITER,
AUTO.MISSION, AUTO.RTL, AUTO.LAND; ArduCopter BRAKE, AUTO, RTL, LAND), and all are audited.

Needs ``../shared`` and a private network namespace
(``bash tests/netns.sh .venv/bin/python -m pytest tests/autopilot/test_operator_commands.py``);
skips, saying why, without them. The take-off and mission helpers are the conformance test's.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest

from adapters.mavlink import MavlinkHub
from gcs_utm.clock import ScaledClock
from gcs_utm.messages import FlightMode
from gcs_utm.model import AuditEntry, Autopilot, Operation, VehicleKind
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm
from tests.autopilot.autopilots import SitlProcess, wait_tcp_listening
from tests.autopilot.test_conformance import (
    CASES,
    SYS,
    Case,
    Rig,
    _config,
    _plan,
    _take_off,
    case_params,
    until,
)

pytestmark = [pytest.mark.network, pytest.mark.timeout(240)]

REAL = [c for c in CASES if c.real and c.kind is VehicleKind.MULTIROTOR]


@pytest.mark.parametrize("case", case_params(REAL))
async def test_operator_hold_resume_rtl_and_land_reach_the_autopilot(
    case: Case, request: pytest.FixtureRequest
) -> None:
    start: Callable[..., SitlProcess] = request.getfixturevalue(
        "px4" if case.autopilot is Autopilot.PX4 else "ardupilot"
    )
    clock = ScaledClock(speed=case.speed)
    plan = _plan(case, leg_m=40.0, speed_mps=5.0, height_m=8.0)
    airspace = Airspace()
    airspace.load(
        [
            Operation(
                id=plan.operation_id,
                icao24=None,
                sys_id=SYS,
                priority=1,
                plan=plan,
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=5.0,
                flight_geometry_m=5.0,
                operational_volume_m=15.0,
            )
        ],
        (),
    )
    records: list[object] = []
    usm = Usm(airspace, clock, record=records.append)
    if case.autopilot is Autopilot.PX4:
        start(instance=0, airframe="quad", speed=case.speed)
        link = "udpin:127.0.0.1:14550"
    else:
        start(instance=0, vehicle="copter", speed=case.speed)
        await asyncio.to_thread(wait_tcp_listening, 5760)
        link = "tcp:127.0.0.1:5760"
    uas = str(plan.operation_id)
    async with MavlinkHub(_config(link), clock, usm) as hub:
        usm.attach_vehicles(hub)
        rig = Rig(case, hub, None)  # type: ignore[arg-type]  # (the sink is the USM)
        await until(
            lambda: (
                (s := usm.statuses_by_sys_id().get(SYS)) is not None
                and s.autopilot is case.autopilot
            ),
            60.0,
            "no HEARTBEAT from the vehicle",
        )
        refused = await usm.operator_command(uas, "hold", operator="pilot", source="test")
        assert (refused.outcome.value, refused.reason) == ("refused", "sysid 1 is disarmed")

        await _take_off(rig, 8.0)
        res = await hub.upload_plan(SYS, plan, start_index=1)
        assert res.ok and res.mode_set, res
        await until(
            lambda: usm.statuses_by_sys_id()[SYS].mode is FlightMode.MISSION, 10.0, "mission"
        )
        held = await usm.operator_command(uas, "hold", operator="pilot", source="test")
        assert (held.outcome.value, held.mode) == ("confirmed", "hold"), held
        resumed = await usm.operator_command(uas, "resume", operator="pilot", source="test")
        assert (resumed.outcome.value, resumed.mode) == ("confirmed", "mission"), resumed
        assert usm.statuses_by_sys_id()[SYS].mode is FlightMode.MISSION
        returned = await usm.operator_command(uas, "rtl", operator="pilot", source="test")
        assert (returned.outcome.value, returned.mode) == ("confirmed", "rtl"), returned
        landing = await usm.operator_command(uas, "land", operator="pilot", source="test")
        assert (landing.outcome.value, landing.mode) == ("confirmed", "land"), landing
        await usm.drain()
    audit = [
        (r.action, r.detail["outcome"])
        for r in records
        if isinstance(r, AuditEntry) and r.action.startswith("operator_")
    ]
    assert audit == [
        ("operator_hold", "refused"),
        ("operator_hold", "confirmed"),
        ("operator_resume", "confirmed"),
        ("operator_rtl", "confirmed"),
        ("operator_land", "confirmed"),
    ]
