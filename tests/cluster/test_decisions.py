"""Decisions across two members on one PostgreSQL database (tests/cluster/harness.py):
B decides for A's UAS1 (B owns UAS2, the higher priority); A owns UAS1's link and pilot.

- a re-decision after A's pilot rejected A's version gets a version number the store
  allocates (unique across lives), so it reaches A's pilot;
- a command B decides for UAS1 (hold, autonomous mode) is not sent by B (no link) but
  reaches A through the store, which sends it to the vehicle and files the outcome that
  B's EM then hears."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import cast

import pytest

from gcs_utm.app.wiring import apply_decision
from gcs_utm.core.emergency import Decision
from gcs_utm.model import (
    Command,
    CommandKind,
    OperationId,
    Recommendation,
    RecommendationState,
)
from gcs_utm.services.usm import Usm
from tests.cluster.harness import Member, config, file_airspace, member
from tests.store.conftest import raw_execute
from tests.store.test_store import _rec

UAS1 = OperationId("UAS1")


async def _pair(url: str, *, command_ok: bool = True) -> tuple[Member, Member]:
    ops = {op.id: op for op in file_airspace(url)}
    a = await member(url, config("A", "c0r0", standby=False), command_ok=command_ok)
    b = await member(url, config("B", "c1r0", standby=False))
    assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
    assert set(a.airspace.ops) == {UAS1} and set(b.airspace.ops) == {OperationId("UAS2")}
    # B watches UAS1 across the border (the exchange makes it foreign there)
    b.node.policy.foreign.add(UAS1)
    b.node._install_foreign([ops[UAS1]])
    return a, b


async def _decide(b: Member, *recs: Recommendation, commands: tuple[Command, ...] = ()) -> None:
    """B's EM decision, carried out as serve carries it (gcs_utm.app.wiring)."""
    await apply_decision(
        cast(Usm, b.usm),
        Decision(recommendations=recs, commands=commands),
        b.store,
        owns=b.node.policy.owns,
        file=b.node.policy.filer,
    )
    b.flush()


def _versions(url: str) -> list[tuple[int, str, int]]:
    rows = raw_execute(url, "SELECT version, state, epoch FROM recommendations ORDER BY version")
    return [(int(v), str(s), int(e)) for v, s, e in rows]  # type: ignore[call-overload]


@pytest.mark.timeout(60)
async def test_a_re_decision_after_the_owners_rejection_reaches_the_pilot(pg_url: str) -> None:
    a, b = await _pair(pg_url)
    ea, eb = a.node.member.epoch, b.node.member.epoch
    try:
        v1 = replace(_rec(), deadline_t_s=time.time() + 600.0, command=None)
        await _decide(b, v1)  # B's EM: v1 for A's UAS1, filed for A
        assert b.usm.proposed == []  # not B's pilot
        await a.node.refresh()
        (asked,) = a.usm.proposed
        assert asked.version == 2 and "decided by life" in asked.reason
        # A's pilot rejects; B's EM hears it for its v1
        a.store.record(asked.transition(RecommendationState.REJECTED, time.time(), "pilot"))
        a.flush()
        await b.node.refresh()
        assert b.em.answers == [(v1.id, 1, False)]
        # B's EM re-decides: its v1 rejected, a new v2 (its own numbering, as the pure EM
        # numbers versions: the previous one + 1), which the owner's v2 already holds
        rejected = v1.transition(RecommendationState.REJECTED, time.time(), "by the operator")
        again = replace(v1, version=2, reason="re-decision after the rejection")
        await _decide(b, rejected, again)
        assert _versions(pg_url) == [
            (1, "rejected", eb),
            (2, "rejected", ea),
            (3, "proposed", eb),  # B's re-decision, filed as the next free version
        ]
        await a.node.refresh()
        assert [r.version for r in a.usm.proposed] == [2, 4]  # A's pilot is prompted again
        assert a.usm.proposed[-1].reason.startswith(f"decided by life {eb}")
        a.flush()
        assert _versions(pg_url)[-1] == (4, "proposed", ea)
        # A's pilot accepts: B's EM hears it under its own number (v2), not the filed v3
        a.store.record(a.usm.proposed[-1].transition(RecommendationState.ACCEPTED, time.time()))
        a.flush()
        await b.node.refresh()
        assert b.em.answers == [(v1.id, 1, False), (v1.id, 2, True)]
        # a later state of B's v2 is written to the filed row (v3), in B's life
        await _decide(b, again.transition(RecommendationState.ACCEPTED, time.time(), "pilot"))
        assert _versions(pg_url)[2] == (3, "accepted", eb)
        assert a.failed == [] and b.failed == []
    finally:
        await a.close()
        await b.close()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("ok", [True, False])
async def test_a_hold_decided_for_another_instances_uas_is_sent_by_its_owner(
    pg_url: str, ok: bool
) -> None:
    a, b = await _pair(pg_url, command_ok=ok)
    ea, eb = a.node.member.epoch, b.node.member.epoch
    try:
        hold = Command(kind=CommandKind.HOLD, operation_id=UAS1)
        now = time.time()
        rec = replace(
            _rec(),
            selected=None,
            alternatives=(),
            new_geofence=None,
            command=hold,
            deadline_t_s=now + 600.0,
        ).transition(RecommendationState.ACCEPTED, now, "autonomous mode")
        await _decide(b, rec, commands=(hold,))  # autonomous: born accepted, with its command
        assert b.usm.commands == []  # B has no link to UAS1: not sent there
        assert _versions(pg_url) == [(1, "accepted", eb)]
        await a.node.refresh()
        assert a.usm.commands == [hold]  # the owner sent it to its vehicle
        assert a.usm.proposed == []  # a decided command is not a prompt
        a.flush()
        outcome = "applied" if ok else "failed"
        assert _versions(pg_url) == [(1, "accepted", eb), (2, outcome, ea)]
        await a.node.refresh()
        assert a.usm.commands == [hold]  # sent once
        await b.node.refresh()
        assert b.em.answers == []  # born accepted: no answer to relay
        assert b.em.outcomes == [(rec.id, 1, ok)]
    finally:
        await a.close()
        await b.close()


@pytest.mark.timeout(60)
async def test_a_stale_command_is_not_sent(pg_url: str) -> None:
    a, b = await _pair(pg_url)
    try:
        hold = Command(kind=CommandKind.HOLD, operation_id=UAS1)
        now = time.time()
        old = replace(
            _rec(), selected=None, alternatives=(), command=hold, deadline_t_s=now - 1.0
        ).transition(RecommendationState.ACCEPTED, now - 30.0, "autonomous mode")
        await _decide(b, old, commands=(hold,))
        await a.node.refresh()
        assert a.usm.commands == []
    finally:
        await a.close()
        await b.close()


class _Vehicles:
    """The MAVLink side of the owner's USM: records the commands sent, acknowledges them."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, Command]] = []

    async def upload_plan(self, *args: object, **kwargs: object) -> object:
        raise AssertionError("no upload expected")

    async def send_command(self, sys_id: int, command: Command) -> _Ack:
        self.sent.append((sys_id, command))
        return _Ack()


class _Ack:
    ok = True
    error = ""


@pytest.mark.timeout(60)
async def test_the_owners_usm_sends_a_forwarded_hold_to_the_vehicle(pg_url: str) -> None:
    """The same hand-over with the owner's real USM and airspace: the hold goes to UAS1's
    system id through the vehicle port, is audited, and suspends the operation."""
    from gcs_utm.app.wiring import Persistence
    from gcs_utm.clock import RealClock
    from gcs_utm.services.airspace import Airspace

    vehicles = _Vehicles()
    real: list[Usm] = []

    def services(store: Persistence) -> tuple[Usm, Airspace]:
        airspace = Airspace(on_operation=store.save_operation)
        usm = Usm(airspace, RealClock(), record=store.record)
        usm.attach_vehicles(vehicles)  # type: ignore[arg-type]
        real.append(usm)
        return usm, airspace

    (uas1,) = [op for op in file_airspace(pg_url) if op.id == UAS1]
    a = await member(pg_url, config("A", "c0r0", standby=False), services=services)
    b = await member(pg_url, config("B", "c1r0", standby=False))
    try:
        assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
        b.node.policy.foreign.add(UAS1)
        b.node._install_foreign([uas1])
        hold = Command(kind=CommandKind.HOLD, operation_id=UAS1)
        now = time.time()
        rec = replace(
            _rec(), selected=None, alternatives=(), command=hold, deadline_t_s=now + 600.0
        ).transition(RecommendationState.ACCEPTED, now, "autonomous mode")
        await _decide(b, rec, commands=(hold,))
        await a.node.refresh()
        assert vehicles.sent == [(1, hold)]
        (usm,) = real
        assert usm.airspace.operation(UAS1).state.value == "suspended"
        a.flush()
        assert [(v, s) for v, s, _e in _versions(pg_url)] == [(1, "accepted"), (2, "applied")]
        audit = raw_execute(pg_url, "SELECT actor, action, subject FROM audit ORDER BY seq")
        assert ("usm", "command_hold", "UAS1") in audit
    finally:
        await a.close()
        await b.close()
