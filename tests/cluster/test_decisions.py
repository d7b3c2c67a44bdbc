"""Decisions across two members on one PostgreSQL database (tests/cluster/harness.py):
B decides for A's UAS1 (B owns UAS2, the higher priority); A owns UAS1's link and pilot.

- a re-decision after A's pilot rejected A's version gets a version number the store
  allocates (unique across lives), so it reaches A's pilot;
- a command B decides for UAS1 (hold, autonomous mode) is not sent by B (no link) but
  reaches A through the store, which sends it to the vehicle and files the outcome that
  B's EM then hears."""

from __future__ import annotations

import asyncio
import contextlib
import time
from dataclasses import dataclass, replace
from typing import cast

import pytest

from gcs_utm.app.wiring import Persistence, apply_decision
from gcs_utm.clock import RealClock
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    OperationId,
    Recommendation,
    RecommendationState,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.emergency import EmergencyService
from gcs_utm.services.usm import Usm
from tests.cluster.harness import Member, config, file_airspace, frame, member
from tests.store.conftest import raw_execute
from tests.store.test_store import _rec, _threat

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


LEASE_S = 1.0


@dataclass
class _Owner:
    """B of the takeover tests: a standby member with a real USM and a real EM service."""

    b: Member
    em: EmergencyManager
    usm: Usm
    service: EmergencyService
    decisions: list[Decision]

    async def decide(self, d: Decision) -> None:
        """B's EM decision, carried out as serve carries it (gcs_utm.app.wiring)."""
        self.decisions.append(d)
        policy = self.b.node.policy
        await apply_decision(self.usm, d, self.b.store, owns=policy.owns, file=policy.filer)
        self.b.flush()

    async def processed(self, n: int) -> None:
        for _ in range(250):
            if self.service.processed >= n:
                return
            await asyncio.sleep(0.02)
        raise AssertionError(f"EM processed {self.service.processed} items, not {n}")


async def _owner(url: str) -> _Owner:
    mon = MonitoringConfig()
    em = EmergencyManager(
        frame(),
        EmergencyConfig(min_response_s=300.0, answer_window_s=300.0),
        TacticalDeconfliction(frame(), DeconflictionConfig(), mon),
        mon,
    )
    box: list[_Owner] = []

    async def on_decision(d: Decision) -> None:
        await box[0].decide(d)

    def snapshot(t_s: float) -> AirspaceSnapshot:
        return AirspaceSnapshot(t_s=t_s, operations={}, tracks={}, geofences=())

    service = EmergencyService(em, snapshot, RealClock(), on_decision)
    usms: list[Usm] = []

    def services(store: Persistence) -> tuple[Usm, Airspace]:
        airspace = Airspace(on_operation=store.save_operation)
        usm = Usm(airspace, RealClock(), record=store.record)

        async def answer_sink(rec: Recommendation, accepted: bool) -> None:
            await service.submit_answer(rec.id, rec.version, accepted)

        usm.attach_answer_sink(answer_sink)  # as gcs_utm.app.wiring attaches them
        usm.attach_operator(service)
        usms.append(usm)
        return usm, airspace

    b = await member(
        url,
        config("B", "c1r0", standby=True, lease_s=LEASE_S),
        services=services,
        emergency=service,
    )
    box.append(_Owner(b, em, usms[0], service, []))
    return box[0]


async def _takeover_pair(url: str) -> tuple[Member, _Owner, Case]:
    """A owns UAS1, B (standby, real USM and EM) owns UAS2 and watches UAS1; the case B's EM
    decides UAS1 in."""
    ops = {op.id: op for op in file_airspace(url)}
    a = await member(url, config("A", "c0r0", standby=False, lease_s=LEASE_S))
    owner = await _owner(url)
    b = owner.b
    assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
    b.node.policy.foreign.add(UAS1)
    b.node._install_foreign([ops[UAS1]])
    now = time.time()
    case = Case(
        threat=replace(_threat(), predicted_event_at_s=now + 600.0),
        action="resolve",
        attempt_t_s=now,
    )
    return a, owner, case


async def _a_dies(a: Member, b: Member) -> None:
    """A makes no more lease rounds; B, a standby renewing its own, takes c0r0 over."""
    assert await b.step_until("gained c0r0") == ["gained c0r0"]
    b.flush()


@pytest.mark.timeout(60)
async def test_after_a_takeover_the_deciders_re_decision_reaches_its_own_pilot(
    pg_url: str,
) -> None:
    """B's EM decided for A's UAS1 (foreign in B); A proposed it to its pilot (v2) and died
    with the prompt pending; B, a standby, took c0r0 over and proposed the prompt again (v3,
    allocated in the store). B's EM numbers its own operations' versions itself: its pending
    version takes the adopted number, so its re-decision (the previous number + 1, as the
    pure EM numbers) is above every stored version and reaches B's pilot through B's real
    USM, and the pilot's answer reaches B's EM under the number the pilot saw."""
    a, owner, case = await _takeover_pair(pg_url)
    b, em, usm_b = owner.b, owner.em, owner.usm
    ea, eb = a.node.member.epoch, b.node.member.epoch
    running = asyncio.create_task(owner.service.run())
    try:
        # B's EM decides v1 for A's UAS1: filed for A, proposed by A to its pilot as v2
        proposed = _rec().selected
        await owner.decide(em.issue(case, UAS1, time.time(), selected=proposed, reason="first"))
        (rid,) = case.rec_ids
        assert usm_b.recommendations == {}  # not B's pilot
        await a.node.refresh()
        assert [r.version for r in a.usm.proposed] == [2]
        a.flush()
        await _a_dies(a, b)
        assert _versions(pg_url) == [(1, "proposed", eb), (2, "proposed", ea), (3, "proposed", eb)]
        held = usm_b.recommendations[rid].rec
        assert (held.version, held.state) == (3, RecommendationState.PROPOSED)
        # B's EM re-decides (supersedes its pending version with the next number)
        await owner.decide(em.issue(case, UAS1, time.time(), selected=proposed, reason="again"))
        held = usm_b.recommendations[rid].rec  # B's pilot is prompted with it
        assert (held.version, held.state, held.reason) == (4, RecommendationState.PROPOSED, "again")
        assert _versions(pg_url)[2:] == [(3, "superseded", eb), (4, "proposed", eb)]
        # B's pilot accepts v4: B's EM hears it for its own current version
        answer = PilotAnswer(
            recommendation_id=rid, version=4, decision=PilotDecision.ACCEPT, t_s=time.time()
        )
        assert (await usm_b.answer(answer)).status.value == "accepted"
        await owner.processed(1)
        answered = em.recommendation(rid)
        assert answered is not None and answered.version == 4
        # accepted (then failed: B's test USM has no vehicle link), not ignored
        assert answered.state is not RecommendationState.PROPOSED
        assert [w for d in owner.decisions for w in d.warnings] == []
        assert a.failed == [] and b.failed == []
    finally:
        running.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await running
        await a.close()
        await b.close()


@pytest.mark.timeout(60)
async def test_after_a_takeover_of_an_accepted_decision_the_next_version_is_above(
    pg_url: str,
) -> None:
    """The same, but A's pilot had accepted A's v2 (B's EM heard it for its v1) and A died
    before the upload's outcome: nothing is pending at the takeover. B's EM's next version
    of the id is numbered above A's v2 (not v2 again, a row of A's life the store refuses)."""
    a, owner, case = await _takeover_pair(pg_url)
    b, em, usm_b = owner.b, owner.em, owner.usm
    ea, eb = a.node.member.epoch, b.node.member.epoch
    running = asyncio.create_task(owner.service.run())
    try:
        proposed = _rec().selected
        await owner.decide(em.issue(case, UAS1, time.time(), selected=proposed, reason="first"))
        (rid,) = case.rec_ids
        await a.node.refresh()
        (asked,) = a.usm.proposed
        a.store.record(asked.transition(RecommendationState.ACCEPTED, time.time(), "pilot"))
        a.flush()
        await b.node.refresh()  # B's EM hears the accept for its v1
        await owner.processed(1)
        heard = em.recommendation(rid)
        assert heard is not None
        assert (heard.version, heard.state) == (1, RecommendationState.ACCEPTED)
        await _a_dies(a, b)
        assert usm_b.recommendations == {}  # nothing pending to resume
        # B's EM decides again for UAS1 (e.g. supervision: the threat is still predicted)
        await owner.decide(em.issue(case, UAS1, time.time(), selected=proposed, reason="again"))
        held = usm_b.recommendations[rid].rec
        assert (held.version, held.state) == (3, RecommendationState.PROPOSED)
        assert _versions(pg_url) == [(1, "accepted", eb), (2, "accepted", ea), (3, "proposed", eb)]
        assert a.failed == [] and b.failed == []
    finally:
        running.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await running
        await a.close()
        await b.close()
