"""Vehicles heard through a MAVLink router by an instance that does not hold their region (a
standby holding nothing, an owner far away): the operation its owner filed for the vehicle's
system id, whatever that operation is called, is loaded as a foreign operation with its
system id, so the vehicle's telemetry feeds an ordinary vehicle track of that operation
instead of an intruder ``sysid:<n>@<address>``; never filed or changed here, and owned once
this instance gains the region."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.clock import RealClock
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import Autopilot, OperationId, OperationState, SysId, VehicleKind
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm
from tests.cluster.harness import config, file_airspace, member


async def test_a_standby_watches_the_vehicles_it_hears_until_it_gains_their_region(
    pg_url: str,
) -> None:
    ops = {op.id: op for op in file_airspace(pg_url)}  # filed by their owners' lives
    uas2 = ops[OperationId("UAS2")]
    assert uas2.sys_id is not None
    heard = {uas2.sys_id}
    c = await member(pg_url, config("C", "c1r0", standby=True), heard=lambda: heard)
    try:
        # C holds nothing yet and hears UAS2's vehicle: not filed here ...
        assert not c.node.files(uas2.id, uas2.plan)
        await c.node.watch_heard()
        # ... but watched: in the airspace with its system id, foreign (not C's to decide)
        watched = c.airspace.ops[uas2.id]
        assert watched.sys_id == uas2.sys_id and uas2.id in c.node.policy.foreign
        assert not c.node.policy.owns(uas2.id) and not c.node.files(uas2.id, uas2.plan)
        assert any("watching UAS2 of another instance (heard)" in e for e in c.usm.events)
        # C gains UAS2's region: the operation is its own now
        assert await c.step() == ["gained c1r0"]
        assert c.node.policy.owns(uas2.id) and c.node.files(uas2.id, uas2.plan)
    finally:
        await c.close()


def _heard_by(sys_id: SysId) -> Usm:
    """A USM that has heard vehicle ``sys_id``: the status the hub reports for it."""
    usm = Usm(Airspace(), RealClock(), record=lambda _r: None)
    usm.on_status(
        VehicleStatus(
            sys_id=sys_id,
            t_s=usm.clock.now_s(),
            autopilot=Autopilot.PX4,
            vehicle_kind=VehicleKind.MULTIROTOR,
            mode=FlightMode.MISSION,
            armed=True,
            landed=False,
            mission_total=2,
        )
    )
    return usm


async def test_a_vehicle_is_recognised_by_its_system_id_whatever_its_operation_is_called(
    pg_url: str,
) -> None:
    ops = {op.id: op for op in file_airspace(pg_url)}
    uas1 = ops[OperationId("UAS1")]  # departs in c0r0
    usm = _heard_by(SysId(9))  # B hears vehicle 9 through the router
    b = await member(pg_url, config("B", "c1r0", standby=False), heard=usm.statuses_by_sys_id)
    try:
        assert await b.step() == ["gained c1r0"]
        # the vehicle's mission departs in c0r0: B does not file it (it would be sys9) ...
        assert not b.node.files(OperationId("sys9"), uas1.plan)
        await b.node.watch_heard()
        assert not any(op.sys_id == 9 for op in b.airspace.ops.values())  # nothing filed yet
        # ... its owner files it under another name (a plan over MQTT naming sys_id 9), next
        # to an earlier flight of the same vehicle that has ended
        named = OperationId("survey-north")
        flown = replace(
            uas1, id=named, sys_id=SysId(9), plan=replace(uas1.plan, operation_id=named)
        )
        old_id = OperationId("survey-old")
        old = replace(
            flown,
            id=old_id,
            state=OperationState.ENDED,
            plan=replace(uas1.plan, operation_id=old_id),
        )
        with b.node.member._open() as s:
            s.begin_life()
            s.save_operation(old)
            s.save_operation(flown)
        await b.node.watch_heard()
        assert b.airspace.ops[named].sys_id == 9 and named in b.node.policy.foreign
        assert old_id not in b.airspace.ops and OperationId("sys9") not in b.airspace.ops
        assert not b.node.policy.owns(named)
        assert any("watching survey-north of another instance (heard)" in e for e in b.usm.events)
    finally:
        await b.close()
