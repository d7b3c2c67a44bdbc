"""EM after a decision (issue 19 item 3, issue 18.5): plans start when the UAS gets them,
an accepted plan that leaves the threat open is re-planned or escalated, a failed upload is
re-planned once and then the safe command is proposed, the joint selection respects
priority and does not escalate because one UAS has no clean option."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.clock import ManualClock
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    CommandKind,
    Maneuver,
    OperationId,
    Recommendation,
    RecommendationState,
    Threat,
    ThreatKind,
    ThreatStatus,
    Track,
    TrackId,
)
from gcs_utm.services.emergency import EmergencyService

MON = MonitoringConfig()


def make_em(answer_delay_s: float | None = None, **cfg: object) -> EmergencyManager:
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    return EmergencyManager(
        sc.FRAME,
        EmergencyConfig(**cfg),  # type: ignore[arg-type]
        td,
        MON,
        answer_delay_s=answer_delay_s,
    )


def at(snap: AirspaceSnapshot, dt_s: float) -> AirspaceSnapshot:
    return replace(snap, t_s=sc.T0_S + dt_s)


def plans(d: Decision) -> list[Recommendation]:
    return [r for r in d.recommendations if r.state is RecommendationState.PROPOSED]


@pytest.mark.parametrize(
    ("delay", "autonomous", "expected", "start_in_s"),
    [
        (None, False, 5.0, 10.0),
        (None, False, 60.0, 25.0),
        (2.0, False, 5.0, 7.0),
        (None, True, 5.0, 5.0),
    ],
    ids=["pilot", "pilot-at-deadline", "auto-answer", "autonomous"],
)
def test_a_plan_starts_after_the_answer_the_upload_and_a_margin(
    delay: float | None, autonomous: bool, expected: float, start_in_s: float
) -> None:
    """Pilot: the expected answer (5 s; never past the deadline, 20 s) + upload 3 s + margin
    2 s; an automatic operator: its delay; autonomous: no answer at all. The plan EM proposes
    leaves the UAS's path then; before that it carries the path's points every 5 s back to
    the earliest the vehicle can have it (an immediate answer plus the upload), and one at
    that instant, so the plan covers every instant the vehicle may fly it."""
    snap, threat = sc.scenario_los_2uas()
    em = make_em(delay, autonomous=autonomous, expected_answer_s=expected)
    assert em.plan_start(threat, snap.t_s) == pytest.approx(snap.t_s + start_in_s)
    d = em.on_threat(threat, snap)
    (rec,) = d.recommendations
    assert rec.selected is not None and rec.selected.plan is not None
    times = [w.t_s - snap.t_s for w in rec.selected.plan.waypoints]
    assert any(abs(t - start_in_s) < 1e-3 for t in times)
    earliest = 3.0 + (delay or 0.0)
    lead = [t for t in times if t < start_in_s - 1e-3]
    assert lead[0] == pytest.approx(earliest)  # from the earliest receipt on (.lead_times)
    back = lead[1:]
    assert back == pytest.approx([start_in_s - 5.0 * k for k in range(len(back), 0, -1)])
    assert all(t > earliest for t in back)
    assert len(back) == int((start_in_s - earliest) // 5.0)
    assert em.manoeuvre_start(rec) == pytest.approx(snap.t_s + start_in_s)


def accept_all(em: EmergencyManager, d: Decision, snap: AirspaceSnapshot) -> list[Recommendation]:
    out = []
    for r in plans(d):
        (acc,) = em.on_answer(r, True, snap).recommendations
        out.append(acc)
    return out


def test_a_threat_still_predicted_after_the_accepted_plan_gets_a_new_version() -> None:
    """Used to be blocked for as long as the accepted recommendation lived."""
    snap, threat = sc.scenario_los_2uas()
    threat = replace(threat, predicted_event_at_s=sc.T0_S + 300.0)
    em = make_em(max_replans=1)
    (acc,) = accept_all(em, em.on_threat(threat, snap), at(snap, 1.0))
    assert acc.selected is not None and acc.selected.plan is not None
    due = em.supervision_due(acc)
    assert due is not None
    # Settled once the plan has left the old one (by the flight geometry) plus the grace.
    assert due > em.manoeuvre_start(acc) + em.config.supervision_grace_s
    settled = due - sc.T0_S
    updated = replace(threat, status=ThreatStatus.UPDATED, updated_at_s=sc.T0_S + 5.0)
    assert em.on_threat(updated, at(snap, 5.0)) == Decision()  # plan not started yet
    assert em.supervise(at(snap, settled - 1.0)) == Decision()
    d = em.on_threat(updated, at(snap, settled + 0.5))
    # The snapshot still holds the filed plans, which meet 3.5 s later: from the earliest
    # receipt on no plan separates them, so the new versions are immediate commands.
    (v2,) = [r for r in plans(d) if r.id == acc.id]
    assert v2.version == acc.version + 1 and v2.command is not None
    assert any(a.action == "supervision" for a in d.audit)
    # Accepted, and the threat still does not close: escalate with the safe command.
    accept_all(em, d, at(snap, settled + 1.0))
    later = settled + 0.5 + 4.0 * em.config.retry_after_s
    d3 = em.supervise(at(snap, later))
    assert d3.escalations and "still predicted" in d3.escalations[0]
    cmd = next(r for r in plans(d3) if r.id == acc.id)
    assert cmd.command is not None and cmd.command.kind is CommandKind.HOLD


def test_a_failed_upload_replans_once_then_proposes_the_safe_command() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    (acc,) = accept_all(em, em.on_threat(threat, snap), at(snap, 1.0))
    d = em.on_outcome(acc.id, acc.version, False, "readback item 1 differs", at(snap, 4.0))
    assert d.recommendations[0].state is RecommendationState.FAILED
    (v2,) = [r for r in plans(d) if r.operation_id == acc.operation_id]
    assert v2.version == acc.version + 1 and v2.selected is not None
    assert not d.escalations
    (acc2,) = accept_all(em, Decision(recommendations=(v2,)), at(snap, 5.0))
    d2 = em.on_outcome(acc2.id, acc2.version, False, "MISSION_ACK error", at(snap, 8.0))
    assert d2.escalations and "failed" in d2.escalations[0]
    (cmd,) = plans(d2)
    assert cmd.command is not None and cmd.command.kind is CommandKind.HOLD
    assert em.pending() == [cmd]  # the threat is never left without a pending decision
    # A verified upload is recorded as applied, nothing else happens.
    ok = em.on_outcome(acc.id, acc.version, True, "mission verified", at(snap, 9.0))
    assert ok == Decision()  # stale version: ignored


def test_a_failed_safe_command_is_escalated_not_proposed_again() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    (acc,) = accept_all(em, em.on_threat(threat, snap), at(snap, 1.0))
    d = em.on_outcome(acc.id, acc.version, False, "no answer", at(snap, 4.0))
    (v2,) = [r for r in plans(d) if r.operation_id == acc.operation_id]
    (acc2,) = accept_all(em, Decision(recommendations=(v2,)), at(snap, 5.0))
    (cmd,) = plans(em.on_outcome(acc2.id, acc2.version, False, "no answer", at(snap, 8.0)))
    (acc3,) = accept_all(em, Decision(recommendations=(cmd,)), at(snap, 9.0))
    d3 = em.on_outcome(acc3.id, acc3.version, False, "command not acknowledged", at(snap, 12.0))
    assert d3.recommendations[0].state is RecommendationState.FAILED
    assert not plans(d3)  # the same hold again would fail again, forever
    assert d3.escalations and "safe command failed" in d3.escalations[0]


def test_battery_failure_escalates_with_land() -> None:
    op = sc.make_operation(
        "A", [(0, 0, 100), (3000, 0, 100)], landing_sites=[(1400, 300, 60)], endurance_s=300.0
    )
    t = sc.T0_S + 100.0
    threat = sc.threat(ThreatKind.LACK_OF_BATTERY, ["A"], t_s=t)
    em = make_em()
    snap = sc.snapshot([op], t_s=t)
    (rec,) = em.on_threat(threat, snap).recommendations
    for _ in range(2):
        (acc,) = em.on_answer(rec, True, snap).recommendations
        d = em.on_outcome(acc.id, acc.version, False, "no link", snap)
        (rec,) = plans(d)
    assert rec.command is not None and rec.command.kind is CommandKind.LAND


class _FakeTD(TacticalDeconfliction):
    """Fixed options and compatibilities, to test the selection rule alone."""

    def __init__(self, options: dict[OperationId, list[Alternative]], ok: set[frozenset[str]]):
        super().__init__(sc.FRAME, DeconflictionConfig(), MON)
        self.options = options
        self.ok = ok

    def resolve_loss_of_separation(
        self,
        threat: Threat,
        snapshot: AirspaceSnapshot,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
        *,
        buffered: bool = True,
    ) -> dict[OperationId, list[Alternative]]:
        return {k: list(v) for k, v in self.options.items()}

    def compatible(
        self, a: Alternative, b: Alternative, snapshot: AirspaceSnapshot, *, buffered: bool = True
    ) -> bool:
        return frozenset({a.detail, b.detail}) in self.ok


def _alt(snap: AirspaceSnapshot, op: str, man: Maneuver, cost: float) -> Alternative:
    plan = snap.operations[OperationId(op)].plan
    return Alternative(
        operation_id=OperationId(op),
        maneuver=man,
        plan=plan if man is Maneuver.KEEP_PLAN else replace(plan, version=2),
        cost=cost,
        risk=0.0,
        detail=f"{op}:{man.value}",
    )


def test_the_higher_priority_uas_moves_only_when_the_lower_cannot() -> None:
    """A (priority 1) can climb at cost 0.5, B (priority 2) at cost 0.01: B used to be moved
    because it was cheaper (madrid_loss_separation moved the fixed wing)."""
    snap, threat = sc.scenario_los_2uas()
    opts: dict[OperationId, list[Alternative]] = {
        OperationId("A"): [
            _alt(snap, "A", Maneuver.KEEP_PLAN, 0.0),
            _alt(snap, "A", Maneuver.GO_UP, 0.5),
        ],
        OperationId("B"): [
            _alt(snap, "B", Maneuver.KEEP_PLAN, 0.0),
            _alt(snap, "B", Maneuver.GO_UP, 0.01),
        ],
    }
    ok = {
        frozenset({"A:keep_plan", "B:go_up"}),
        frozenset({"A:go_up", "B:keep_plan"}),
        frozenset({"A:go_up", "B:go_up"}),
    }
    em = EmergencyManager(sc.FRAME, EmergencyConfig(), _FakeTD(opts, ok), MON)
    d = em.on_threat(threat, snap)
    (rec,) = plans(d)
    assert rec.operation_id == "A" and rec.selected is not None
    assert rec.selected.maneuver is Maneuver.GO_UP
    # Only when A has nothing compatible with B keeping its plan, B moves.
    ok2 = {frozenset({"A:keep_plan", "B:go_up"})}
    d2 = EmergencyManager(sc.FRAME, EmergencyConfig(), _FakeTD(opts, ok2), MON).on_threat(
        threat, snap
    )
    (rec2,) = plans(d2)
    assert rec2.operation_id == "B"


def test_one_uas_without_a_clean_option_does_not_block_the_other() -> None:
    """X flies inside a geofence (its every option, its current plan included, is flagged);
    Y crosses it and can move: Y gets a recommendation, X is escalated on its own; the case
    used to escalate with no recommendation at all."""
    x = sc.make_operation("X", [(-1000, 0, 100), (1000, 0, 100)])
    y = sc.make_operation("Y", [(0, -1000, 100), (0, 1000, 100)], priority=2)
    fence = replace(sc.cylinder("zone", 0.0, 0.0, 3000.0), exempt=(OperationId("Y"),))
    snap = sc.snapshot([x, y], [fence])
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["X", "Y"], event_in_s=100)
    em = make_em()
    d = em.on_threat(threat, snap)
    recs = plans(d)
    assert [r.operation_id for r in recs] == ["Y"]
    assert recs[0].selected is not None and recs[0].selected.maneuver is not Maneuver.KEEP_PLAN
    assert d.escalations and "X has no conflict-free option" in d.escalations[0]
    assert not any("no conflict-free combination" in e for e in d.escalations)


async def test_the_service_hears_upload_outcomes_and_supervises() -> None:
    snap, threat = sc.scenario_los_2uas()
    clock = ManualClock(snap.t_s)
    em = make_em()
    got: list[Decision] = []

    async def sink(d: Decision) -> None:
        got.append(d)

    svc = EmergencyService(em, lambda t: replace(snap, t_s=t), clock, sink)
    task = asyncio.create_task(svc.run())
    try:
        await svc.submit_threats([threat])
        await _until(lambda: bool(svc.pending()))
        (rec,) = svc.pending()
        await svc.submit_answer(rec.id, rec.version, True)
        await _until(lambda: em.pending() == [] and len(got) >= 2)
        acc = em.recommendation(rec.id)
        assert acc is not None
        await svc.update(acc.transition(RecommendationState.FAILED, snap.t_s, "nack"))
        await _until(lambda: bool(svc.pending()))
        assert svc.pending()[0].version == rec.version + 1
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def _until(cond: object, steps: int = 2000) -> None:
    for _ in range(steps):
        if callable(cond) and cond():
            return
        await asyncio.sleep(0)
    raise AssertionError("condition not reached")


async def test_the_service_supervises_on_its_own_clock() -> None:
    """Monitoring reports a persisting threat only when it changes: the service's tick asks
    EM to supervise, and the accepted plan that left the threat open gets a new version."""
    snap, threat = sc.scenario_los_2uas()
    clock = ManualClock(snap.t_s)
    em = make_em()
    got: list[Decision] = []

    async def sink(d: Decision) -> None:
        got.append(d)

    svc = EmergencyService(em, lambda t: replace(snap, t_s=t), clock, sink)
    task = asyncio.create_task(svc.run())
    try:
        await svc.submit_threats([threat])
        await _until(lambda: bool(svc.pending()))
        (rec,) = svc.pending()
        await svc.submit_answer(rec.id, rec.version, True)
        await _until(lambda: em.pending() == [] and em.supervising())
        acc = em.recommendation(rec.id)
        assert acc is not None
        due = em.supervision_due(acc)
        assert due is not None
        clock.advance(due - snap.t_s + 1.0)
        await _until(lambda: bool(svc.pending()))
        assert svc.pending()[0].version == rec.version + 1
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def test_supervision_keeps_a_standing_plan_that_is_still_the_choice() -> None:
    """Once the applied plan is in the airspace and keeping it is conflict-free, a threat
    that Monitoring has not closed yet (its predictor extrapolates the track until the UAS
    turns) gets no new version and no escalation: the standing plan is kept (it used to be
    replaced by a hold command, stopping a multirotor in the path of the other)."""
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    (acc,) = accept_all(em, em.on_threat(threat, snap), at(snap, 1.0))
    assert acc.selected is not None and acc.selected.plan is not None
    ops = dict(snap.operations)
    ops[acc.operation_id] = replace(ops[acc.operation_id], plan=acc.selected.plan)
    flown = replace(snap, operations=ops)
    due = em.supervision_due(acc)
    assert due is not None
    d = em.supervise(replace(flown, t_s=due + 0.5))
    assert not d.escalations and not plans(d)
    assert any(a.action == "supervision" for a in d.audit)


def test_overlapping_threats_build_on_each_others_recommended_plans() -> None:
    """Three UAS meet at one point: the pairwise threats are decided one after the other,
    before any plan is uploaded. Each decision builds on the plans the earlier ones
    recommended, so the plans that end up recommended keep all three apart."""
    from gcs_utm.core.monitoring.strategic import strategic_check

    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=1)
    b = sc.make_operation("B", [(1000, 0, 100), (-1000, 0, 100)], priority=2)
    c = sc.make_operation("C", [(0, -1000, 100), (0, 1000, 100)], priority=3)
    snap = sc.snapshot([a, b, c])
    em = make_em()
    latest: dict[OperationId, Recommendation] = {}
    for tid, pair in (("t1", ["A", "B"]), ("t2", ["A", "C"]), ("t3", ["B", "C"])):
        threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, pair, tid=tid, event_in_s=100)
        for r in plans(em.on_threat(threat, snap)):
            if r.selected is not None:  # (a case no plan resolves gets an immediate command)
                latest[r.operation_id] = r
    ops = dict(snap.operations)
    for k, r in latest.items():
        assert r.selected is not None and r.selected.plan is not None
        ops[k] = replace(ops[k], plan=r.selected.plan)
    assert latest
    assert strategic_check(list(ops.values()), (), sc.FRAME, MON).conflicts == ()


def test_an_escalated_case_is_retried_on_the_supervision_tick() -> None:
    """Monitoring sends no update while a threat stays the same: the tick retries a case
    that ended in escalation every retry_after_s (it used to wait for an update forever)."""
    snap, threat = sc.scenario_los_2uas()
    opts: dict[OperationId, list[Alternative]] = {
        OperationId("A"): [
            _alt(snap, "A", Maneuver.KEEP_PLAN, 0.0),
            _alt(snap, "A", Maneuver.GO_UP, 0.5),
        ],
        OperationId("B"): [_alt(snap, "B", Maneuver.KEEP_PLAN, 0.0)],
    }
    td = _FakeTD(opts, set())
    em = EmergencyManager(sc.FRAME, EmergencyConfig(), td, MON)
    d = em.on_threat(threat, snap)
    assert d.escalations and all(r.selected is None for r in plans(d))
    (cmd,) = plans(d)  # the escalation's immediate command: the pilot refuses it
    assert cmd.command is not None
    em.on_answer(cmd, False, at(snap, 1.0))
    assert em.supervising()
    assert em.supervise(at(snap, 10.0)) == Decision()  # not before retry_after_s
    td.ok = {frozenset({"A:go_up", "B:keep_plan"})}  # the airspace changed meanwhile
    d2 = em.supervise(at(snap, em.config.retry_after_s + 1.0))
    (rec,) = plans(d2)
    assert rec.operation_id == "A" and rec.selected is not None
    assert rec.selected.maneuver is Maneuver.GO_UP


def test_a_predicted_loss_with_clean_plans_gets_an_immediate_command() -> None:
    """Every plan already keeps separation while the tracks predict the loss (a UAS flies
    off its plan): EM does not keep all. It warns at once and, when the event is within the
    lead plus 10 s, escalates and proposes an immediate command for the UAS whose track is
    off its plan; the audit says which and why."""
    snap, threat = sc.scenario_los_2uas()
    # A's track is 40 m north of its plan, heading at B (B is where its plan says)
    la, lo = sc.FRAME.point_to_wgs84(-1000.0, 40.0)
    track = Track(
        id=TrackId("A"),
        t_s=snap.t_s,
        lat_deg=la,
        lon_deg=lo,
        alt_amsl_m=100.0,
        east_m=-1000.0,
        north_m=40.0,
        vel_enu_mps=(10.0, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=OperationId("A"),
    )
    snap = replace(snap, tracks={TrackId("A"): track})
    opts = {
        OperationId("A"): [_alt(snap, "A", Maneuver.KEEP_PLAN, 0.0)],
        OperationId("B"): [_alt(snap, "B", Maneuver.KEEP_PLAN, 0.0)],
    }
    td = _FakeTD(opts, {frozenset({"A:keep_plan", "B:keep_plan"})})
    em = EmergencyManager(sc.FRAME, EmergencyConfig(), td, MON)
    d0 = em.on_threat(threat, snap)  # the event is 100 s ahead: warned, command deferred
    assert d0.warnings and "(A off its plan)" in d0.warnings[0]
    (audit,) = (a for a in d0.audit if a.action == "decision")
    assert "not where its plan says" in str(audit.detail["all_kept"])
    assert "proposed or deferred (its own audit)" in str(audit.detail["all_kept"])
    assert not plans(d0) and not d0.escalations
    (later,) = (a for a in d0.audit if a.action == "immediate")
    assert "deferred to 83.0 s from now" in str(later.detail["reason"])  # 100 - 7 - 10
    assert em.supervise(at(snap, 82.0)) == Decision()
    d = em.supervise(at(snap, 83.5))
    assert not d.warnings  # said once per case
    (rec,) = plans(d)
    assert rec.operation_id == "A" and rec.selected is None and rec.command is not None
    assert d.escalations and "proposed" in d.escalations[0]
    (why,) = (a for a in d.audit if a.action == "immediate")
    assert why.detail["selected"] == {"A": rec_action(rec)}
    again = em.supervise(at(snap, 84.5))
    assert again == Decision()  # the command is pending: nothing new


def rec_action(rec: Recommendation) -> str:
    """hold, climb or descend: what an immediate command does."""
    assert rec.command is not None
    if rec.command.kind is CommandKind.HOLD:
        return "hold"
    assert rec.command.target is not None
    return "climb" if rec.command.target.alt_amsl_m > 100.0 else "descend"


def test_an_accepted_plan_older_than_the_airspace_plan_is_not_put_back() -> None:
    """Without outcome reports an accepted recommendation stays ACCEPTED: once the airspace
    holds a newer plan for that UAS, a later decision must not decide on the older one."""
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    (acc,) = accept_all(em, em.on_threat(threat, snap), at(snap, 1.0))
    assert acc.selected is not None and acc.selected.plan is not None
    uas = acc.operation_id
    other = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], tid="t9", event_in_s=100)
    case = em.case(threat.id)
    assert case is not None
    later = at(snap, 30.0)
    newer = replace(snap.operations[uas].plan, version=7, created_t_s=later.t_s)
    ops = {**later.operations, uas: replace(later.operations[uas], plan=newer)}
    em.on_threat(other, replace(later, operations=ops))
    seen = em.case(other.id)
    assert seen is not None and seen.operations[uas].plan.version == 7
    # ...while an accepted plan newer than the airspace's is what the next decision uses.
    em2 = make_em()
    (acc2,) = accept_all(em2, em2.on_threat(threat, snap), at(snap, 1.0))
    em2.on_threat(other, at(snap, 2.0))
    seen2 = em2.case(other.id)
    assert seen2 is not None and acc2.selected is not None
    assert seen2.operations[acc2.operation_id].plan.waypoints == acc2.selected.plan.waypoints


def test_a_final_safe_command_in_force_is_not_proposed_again() -> None:
    """GNSS degradation does not clear while the UAS lands: once LAND is accepted and applied,
    supervision used to propose LAND again every retry_after_s (use case 2 asked the pilot the
    same question seven times while the vehicle was already landing). It is audited once."""
    op = sc.make_operation("A", [(0, 0, 100), (3000, 0, 100)], landing_sites=[(1400, 300, 60)])
    t = sc.T0_S + 100.0
    threat = sc.threat(ThreatKind.GNSS_DEGRADATION, ["A"], t_s=t)
    em = make_em(max_replans=0)
    snap = sc.snapshot([op], t_s=t)
    rec = next(r for r in em.on_threat(threat, snap).recommendations)
    now = t
    commands, audits = [], []
    for _ in range(6):  # answer, apply, let it settle, supervise: until LAND is in force
        now += 1.0
        (acc,) = em.on_answer(rec, True, replace(snap, t_s=now)).recommendations
        em.on_outcome(acc.id, acc.version, True, "applied", replace(snap, t_s=now))
        if acc.command is not None:
            commands.append(acc.command.kind)
        for _tick in range(5):  # supervision ticks, retry_after_s apart
            now = max(now, em.supervision_due(acc) or now) + em.config.retry_after_s + 1.0
            d = em.supervise(replace(snap, t_s=now))
            audits += [str(a.detail) for a in d.audit]
            if plans(d):
                break
        if not plans(d):
            break
        (rec,) = plans(d)
    assert commands == [CommandKind.LAND], commands
    assert not d.escalations
    final = [a for a in audits if "final safe command in force" in a]
    assert len(final) == 1, audits
