"""Vehicles heard through a MAVLink router by an instance that does not hold their region (a
standby holding nothing, an owner far away): their operation, filed by its owner, is loaded
as a foreign operation with its system id, so their telemetry feeds an ordinary vehicle track
of that operation instead of an intruder ``sysid:<n>@<address>``; never filed or changed
here, and owned once this instance gains the region."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.model import OperationId
from tests.cluster.harness import config, file_airspace, member


async def test_a_standby_watches_the_vehicles_it_hears_until_it_gains_their_region(
    pg_url: str,
) -> None:
    ops = {op.id: op for op in file_airspace(pg_url)}  # filed by their owners' lives
    uas2 = ops[OperationId("UAS2")]
    c = await member(pg_url, config("C", "c1r0", standby=True))
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


async def test_a_vehicle_not_filed_yet_is_looked_for_again(pg_url: str) -> None:
    ops = {op.id: op for op in file_airspace(pg_url)}
    uas1 = ops[OperationId("UAS1")]
    b = await member(pg_url, config("B", "c1r0", standby=False))
    try:
        assert await b.step() == ["gained c1r0"]
        renamed = OperationId("sys9")  # a vehicle's mission its owner has not filed yet
        assert not b.node.files(renamed, uas1.plan)
        await b.node.watch_heard()
        assert renamed not in b.airspace.ops
        with b.node.member._open() as s:  # its owner files it
            s.begin_life()
            s.save_operation(
                replace(uas1, id=renamed, plan=replace(uas1.plan, operation_id=renamed))
            )
        await b.node.watch_heard()
        assert renamed in b.airspace.ops and renamed in b.node.policy.foreign
    finally:
        await b.close()
