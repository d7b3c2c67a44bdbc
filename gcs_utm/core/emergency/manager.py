"""Emergency Management: threat -> policy -> TD alternatives -> joint selection -> actions.

Pure (no I/O, no clock: time is ``AirspaceSnapshot.t_s``). State: the open cases (one per
threat id, :class:`~.decision.Case`) and the current version of every recommendation.

Guarantees:
- every plan change or command leaves as a :class:`Recommendation` with a deadline
  (predicted event time minus ``deadline_margin_s``, never less than ``min_response_s`` from
  now); in autonomous mode it is born ACCEPTED and commands are also returned to execute;
- a rejection or an expiry re-plans without the refused maneuver (a new version of the id) up
  to ``max_replans`` times, then escalates; no feasible alternative: EM escalates (no drop);
- every decision is audited (:class:`AuditEntry`: alternatives, cost, risk, weights, reason).

Composition: the manager is an orchestrator. It holds the state and an
:class:`~.context.EmContext` over it, and dispatches each case by its :class:`~.config.Action`
to a part that receives that context and never imports the manager: the multi-UAS joint
selection (here), :mod:`.single` (one UAS, intruders), :mod:`.geofences` (suspend, link loss,
alert areas), :mod:`.immediate` and :mod:`.endpoint` (commands, end points), and for what
follows a decision :mod:`.supervision`, :mod:`.expiry`, :mod:`.adoption`, :mod:`.closing`,
:mod:`.recheck`.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from dataclasses import replace

from gcs_utm.core.deconfliction import TacticalDeconfliction
from gcs_utm.core.emergency.adoption import adopt_case
from gcs_utm.core.emergency.clearance import with_clearance
from gcs_utm.core.emergency.closing import close_threat, supersede_pending
from gcs_utm.core.emergency.config import Action, EmergencyConfig, ExpiryAction
from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import ONE_SHOT, SINGLE_MANEUVERS, Case, Decision, Mode
from gcs_utm.core.emergency.expiry import expire
from gcs_utm.core.emergency.failed_safe import after_failure
from gcs_utm.core.emergency.geofences import area, link_loss, suspend
from gcs_utm.core.emergency.immediate import keep_all, late_reason, propose
from gcs_utm.core.emergency.lead import ResponseTimes
from gcs_utm.core.emergency.options import detail, intended
from gcs_utm.core.emergency.recheck import plan_problem
from gcs_utm.core.emergency.selection import (
    STAY_DETAIL,
    Selection,
    TieredSelection,
    is_stay,
    select_by_priority,
    stay,
)
from gcs_utm.core.emergency.single import intruder, single
from gcs_utm.core.emergency.supervision import on_outcome, settled_at, supervise_case
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    Geofence,
    Maneuver,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
)

KEPT_REASON = (
    "every plan (re-timed from the vehicles' progress; a finished fixed wing's as its loiter "
    "circle) keeps the buffered minima, while Monitoring predicts the loss from the tracks: "
    "a UAS is not where its plan says"
)
"""Why a multi-UAS decision that moves nobody moves nobody (``all_kept`` in its audit)."""


def _warn(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision:
    """The ``warn`` action: an operator warning, audited."""
    t = case.threat
    msg = f"{t.kind.value}: {', '.join(t.uas_ids)} {t.message}".strip()
    return Decision(
        warnings=(msg,), audit=(em.audit(snapshot.t_s, "warn", t.id, {"message": msg}),)
    )


_WHOLE_CASE: dict[Action, Callable[[EmContext, Case, AirspaceSnapshot], Decision]] = {
    Action.WARN: _warn,
    Action.SUSPEND_AND_GEOFENCE: suspend,
    Action.ALERT_AND_GEOFENCE: link_loss,
    Action.GEOFENCE_FROM_AREA: area,
}
"""The actions decided for the whole case at once by a part (the multi-UAS one is the
manager's own; the others are decided per UAS: :func:`.single.single`, intruders)."""


class EmergencyManager:
    def __init__(
        self,
        frame: LocalFrame,
        config: EmergencyConfig,
        td: TacticalDeconfliction,
        monitoring: MonitoringConfig,
        *,
        answer_delay_s: float | None = None,
    ) -> None:
        """``answer_delay_s``: when an automatic operator answers (``--auto-accept``), its
        delay; None when a person answers (then ``emergency.expected_answer_s``). Measured
        answer, upload and command times go to :attr:`lead` (see .lead)."""
        self.frame = frame
        self.config = config
        self.td = td
        self.monitoring = monitoring
        self.lead = ResponseTimes(config, answer_delay_s)
        self._cases: dict[ThreatId, Case] = {}
        self._recs: dict[RecommendationId, Recommendation] = {}
        # versions of an id numbered elsewhere (another instance of a cluster): the next
        # version of the id is above them
        self._floors: dict[RecommendationId, int] = {}
        self.ctx = EmContext(
            frame=frame,
            config=config,
            td=td,
            monitoring=monitoring,
            lead=self.lead,
            cases=self._cases,
            recs=self._recs,
            floors=self._floors,
            decide=self._handle,
        )
        """What the parts are handed (see .context)."""
        # the parts' bookkeeping, offered as the manager's own
        self.recommendation = self.ctx.recommendation
        self.record = self.ctx.record
        self.case = self.ctx.case
        self.open_threats = self.ctx.open_threats
        self.audit = self.ctx.audit
        self.issue = self.ctx.issue
        self.plan_start = self.ctx.plan_start
        self.manoeuvre_start = self.ctx.manoeuvre_start
        self.earliest_receipt = self.ctx.earliest_receipt

    # ---- queries ----------------------------------------------------------------------------
    def pending(self) -> list[Recommendation]:
        """Recommendations waiting for an answer, earliest deadline first."""
        recs = [r for r in self._recs.values() if r.state is RecommendationState.PROPOSED]
        return sorted(recs, key=lambda r: r.deadline_t_s)

    def forget_operations(self, op_ids: Collection[OperationId]) -> None:
        """Operations the airspace forgot (services/retention.py): their recommendations leave
        memory, except one an open case still refers to (the store keeps the record)."""
        self.lead.forget(op_ids)
        kept = {rid for case in self._cases.values() for rid in case.rec_ids}
        for rid in [r for r, x in self._recs.items() if x.operation_id in op_ids]:
            if rid not in kept:
                del self._recs[rid]
                self._floors.pop(rid, None)

    def continue_after(self, rec_id: RecommendationId, version: int) -> None:
        """The next version of ``rec_id`` is numbered above ``version`` (taken elsewhere)."""
        if rec_id in self._recs:
            self._floors[rec_id] = max(self._floors.get(rec_id, 0), version)

    # ---- entry points -----------------------------------------------------------------------
    def on_threat(self, threat: Threat, snapshot: AirspaceSnapshot) -> Decision:
        if threat.status is ThreatStatus.CLOSED:
            return self.on_threat_closed(threat)
        case = self._cases.get(threat.id)
        if case is not None:
            case.threat = threat
            return self._persisting(case, snapshot)
        action = self.config.action_for(threat.kind)
        case = Case(threat=threat, action=action, attempt_t_s=snapshot.t_s)
        self._cases[threat.id] = case
        return self._handle(case, snapshot)

    def _persisting(self, case: Case, snapshot: AirspaceSnapshot) -> Decision:
        """The threat of ``case`` persists. A pending recommendation stands until answered,
        expired or the threat closes; an accepted one is supervised (see .supervision);
        one-shot actions (warning, geofence creation) are done; a case that ended in
        escalation is retried every retry_after_s with its refused maneuvers still excluded
        (no churn every monitoring cycle)."""
        if case.action in ONE_SHOT or self.ctx.pending_in(case):
            return Decision()
        if self.ctx.in_force(case):
            return supervise_case(self.ctx, case, snapshot)
        if snapshot.t_s - case.attempt_t_s < self.config.retry_after_s:
            return Decision()
        case.attempt_t_s = snapshot.t_s
        case.replans.clear()
        return self._handle(case, snapshot)

    def supervising(self) -> bool:
        """Is any open case waiting on an accepted plan or on a retry after an escalation
        (so :meth:`supervise` has work)?"""
        return any(
            c.action not in ONE_SHOT and not self.ctx.pending_in(c) for c in self._cases.values()
        )

    def supervise(self, snapshot: AirspaceSnapshot) -> Decision:
        """Periodic supervision of every open case (Monitoring reports a persisting threat
        only when it changes): accepted plans are supervised (see :mod:`.supervision`) and a
        case that ended in escalation is retried every retry_after_s."""
        d = Decision()
        for case in list(self._cases.values()):
            d = d.merge(self._persisting(case, snapshot))
        return d

    def on_outcome(
        self,
        rec_id: RecommendationId,
        version: int,
        applied: bool,
        reason: str,
        snapshot: AirspaceSnapshot,
    ) -> Decision:
        """The upload (or command) of an accepted recommendation was verified or failed."""
        return on_outcome(self.ctx, rec_id, version, applied, reason, snapshot, after_failure)

    def on_answer(
        self, rec: Recommendation, accepted: bool, snapshot: AirspaceSnapshot
    ) -> Decision:
        now = snapshot.t_s
        cur = self._recs.get(rec.id)
        if (
            cur is None
            or cur.version != rec.version
            or cur.state is not RecommendationState.PROPOSED
        ):
            state = "unknown" if cur is None else f"v{cur.version} {cur.state.value}"
            msg = f"answer to {rec.id} v{rec.version} ignored: current is {state}"
            return Decision(
                warnings=(msg,),
                audit=(self.audit(now, "answer_ignored", rec.id, {"reason": msg}),),
            )
        if accepted:
            new = cur.transition(RecommendationState.ACCEPTED, now, "accepted by the operator")
            self._recs[new.id] = new
            return Decision(
                recommendations=(new,),
                audit=(self.audit(now, "accepted", rec.id, {"version": rec.version}),),
            )
        new = cur.transition(RecommendationState.REJECTED, now, "rejected by the operator")
        self._recs[new.id] = new
        d = Decision(
            recommendations=(new,),
            audit=(self.audit(now, "rejected", rec.id, {"version": rec.version}),),
        )
        return d.merge(self._replan(new, snapshot, "rejected"))

    def on_expired(self, rec: Recommendation, snapshot: AirspaceSnapshot) -> Decision:
        """No answer in time: see :mod:`.expiry` (the safe command proposed again, or a
        re-plan as after a rejection: ``expiry_action``)."""
        d, new = expire(self.ctx, rec, snapshot)
        if new is None or self.config.expiry_action != ExpiryAction.REPLAN:
            return d
        return d.merge(self._replan(new, snapshot, "expired"))

    def on_threat_closed(self, threat: Threat) -> Decision:
        """The case of a CLOSED ``threat`` ends: its pending proposals are superseded."""
        return supersede_pending(self.ctx, threat)

    def close_threat(self, threat: Threat) -> Decision:
        """As :meth:`on_threat_closed`, and the geofences its case created go (.closing)."""
        return close_threat(self.ctx, threat)

    def adopt_case(
        self,
        threat: Threat,
        *,
        inherited: Threat,
        recommendations: Sequence[Recommendation],
        geofences: Sequence[Geofence],
        now: float,
    ) -> Decision | None:
        """An earlier life's case of ``inherited`` taken over by ``threat`` (.adoption)."""
        return adopt_case(
            self.ctx,
            threat,
            inherited=inherited,
            recommendations=recommendations,
            geofences=geofences,
            now=now,
        )

    def plan_problem(self, rec: Recommendation, snapshot: AirspaceSnapshot) -> str:
        """Why the accepted plan of ``rec`` must not be uploaded now ("" when it may;
        .recheck)."""
        return plan_problem(self.ctx, rec, snapshot)

    def supervision_due(self, rec: Recommendation) -> float | None:
        """When an accepted ``rec`` is settled (see :mod:`.supervision`); None when its case
        is closed."""
        case = self._cases.get(rec.threat_id)
        return None if case is None else settled_at(self.ctx, case, rec)

    # ---- internals --------------------------------------------------------------------------
    def _handle(self, case: Case, snapshot: AirspaceSnapshot) -> Decision:
        """The case's action (``[emergency] policy``), done by its part: for the whole case
        at once, or one decision per UAS of the threat."""
        a = case.action
        if a is Action.ALTERNATIVE_PLANS:
            return self._multi(case, snapshot)
        whole = _WHOLE_CASE.get(a)
        if whole is not None:
            return whole(self.ctx, case, snapshot)
        if a is not Action.VERTICAL_AVOIDANCE and a not in SINGLE_MANEUVERS:
            raise AssertionError(f"unhandled action {a!r}")  # EmergencyConfig validates actions
        d = Decision()
        for op_id in case.threat.uas_ids:
            if a is Action.VERTICAL_AVOIDANCE:
                d = d.merge(intruder(self.ctx, case, op_id, snapshot))
            else:
                d = d.merge(single(self.ctx, case, op_id, snapshot, SINGLE_MANEUVERS[a]))
        return d

    # -- multi-UAS
    def _multi(self, case: Case, snapshot: AirspaceSnapshot) -> Decision:
        """Charged cords + joint selection under the priority rule (selection tiers). A UAS
        without a verified option stays on its plan (escalated for it) while the others
        move. An immediate command is proposed (.immediate) when the event is nearer than a
        new plan's start, when no combination resolves the conflict, or when every plan
        (re-timed from the vehicles' progress by the snapshot provider) is kept."""
        snapshot = intended(self.ctx, snapshot, case)
        case.operations = dict(snapshot.operations)
        now = snapshot.t_s
        t = case.threat
        late = late_reason(self.ctx, case, snapshot)  # with plans in force: only if they change
        if late and not self.ctx.in_force(case):
            return propose(self.ctx, case, snapshot, late, t.uas_ids)
        options, tiered, compatible = self._joint(case, snapshot, buffered=True)
        if tiered is None:
            # No combination keeps the vehicles' tracking tolerances free: the best one that
            # keeps the bare minima beats no decision at all.
            options, tiered, compatible = self._joint(case, snapshot, buffered=False)
        sel = None if tiered is None else tiered.selection
        info = detail(self.ctx, options, sel, "loss of separation: charged cords + joint selection")
        if tiered is None:
            msg = f"{t.id}: no conflict-free combination of alternatives for {', '.join(t.uas_ids)}"
            audit = Decision(audit=(self.audit(now, "escalation", t.id, info),))
            return audit.merge(propose(self.ctx, case, snapshot, msg, t.uas_ids))
        info["moved_up_to_priority"] = tiered.moved_up_to_priority
        kept = all(a.maneuver is Maneuver.KEEP_PLAN for a in tiered.selection.chosen.values())
        if kept:
            info["all_kept"] = KEPT_REASON + (
                "; a plan of this case is in force: nothing is proposed"
                if self.ctx.in_force(case)
                else "; the immediate command is proposed or deferred (its own audit)"
            )
        d = Decision(audit=(self.audit(now, "decision", t.id, info),))
        if late and not kept:
            return d.merge(propose(self.ctx, case, snapshot, late, t.uas_ids))
        d = d.merge(self._issue_joint(case, tiered.selection, options, compatible, now))
        if kept and not self.ctx.in_force(case):
            d = d.merge(keep_all(self.ctx, case, snapshot))  # never keep all: see .immediate
        return d

    def _joint(
        self, case: Case, snapshot: AirspaceSnapshot, *, buffered: bool
    ) -> tuple[
        dict[OperationId, list[Alternative]],
        TieredSelection | None,
        Callable[[Alternative, Alternative], bool],
    ]:
        """TD's options for the case (with or without the tracking tolerances, see
        ``TacticalDeconfliction.pair_minima``) and their joint selection by priority."""
        now = snapshot.t_s
        cfg = self.config
        t = case.threat
        options = self.td.resolve_loss_of_separation(
            t,
            snapshot,
            start_t_s=self.plan_start(t, now),
            lead_in_from_t_s=self.earliest_receipt(now, t.uas_ids),
            buffered=buffered,
        )
        for op_id, alts in options.items():
            banned = case.excluded.get(op_id, set())
            options[op_id] = [x for x in alts if x.maneuver not in banned]
        ops = snapshot.operations
        stays = {
            k: stay(k, ops[k].plan)
            for k, alts in options.items()
            if k in ops and not any(x.maneuver is Maneuver.KEEP_PLAN for x in alts)
        }
        memo: dict[tuple[int, int], bool] = {}
        pair = set(t.uas_ids)

        def compatible(x: Alternative, y: Alternative) -> bool:
            if (
                x.maneuver is Maneuver.KEEP_PLAN
                and y.maneuver is Maneuver.KEEP_PLAN
                and not {x.operation_id, y.operation_id} <= pair
            ):
                # Two unchanged plans outside this threat's pair: their conflict, if
                # any, is another threat's, and this decision neither causes nor can
                # fix it (requiring it made every combination fail, and nothing moved).
                return True
            key = (id(x), id(y)) if id(x) < id(y) else (id(y), id(x))
            if key not in memo:
                memo[key] = self.td.compatible(x, y, snapshot, buffered=buffered)
            return memo[key]

        tiered = select_by_priority(
            options,
            {k: ops[k].priority for k in options if k in ops},
            stays,
            alpha=cfg.alpha,
            beta=cfg.beta,
            compatible=compatible,
            max_nodes=cfg.max_combinations,
        )
        return options, tiered, compatible

    def _issue_joint(
        self,
        case: Case,
        sel: Selection,
        options: dict[OperationId, list[Alternative]],
        compatible: Callable[[Alternative, Alternative], bool],
        now: float,
    ) -> Decision:
        """Recommendations for the UAS whose selected option changes their plan."""
        t = case.threat
        d = Decision()
        for op_id, alt in sel.chosen.items():
            case.modes[op_id] = Mode.MULTI
            rid = RecommendationId(f"{t.id}/{op_id}")
            prev = self._recs.get(rid)
            if is_stay(alt):
                msg = f"{t.id}: {op_id} has {STAY_DETAIL}; the others move around it"
                d = d.merge(Decision(escalations=(msg,)))
            if alt.maneuver is Maneuver.KEEP_PLAN:
                if prev is not None and prev.state is RecommendationState.PROPOSED:
                    old = prev.transition(RecommendationState.SUPERSEDED, now, "no longer needed")
                    self._recs[rid] = old
                    d = d.merge(Decision(recommendations=(old,), superseded=(rid,)))
                continue
            if (
                prev is not None
                and prev.state in (RecommendationState.PROPOSED, RecommendationState.ACCEPTED)
                and prev.selected is not None
                and prev.selected.plan == alt.plan
            ):
                continue  # unchanged for this UAS: keep the standing version
            others = [c for k, c in sel.chosen.items() if k != op_id]
            shown = [
                x for x in options[op_id] if x is not alt and all(compatible(x, c) for c in others)
            ]
            ops = case.operations  # the separation each option keeps from the others' choice
            d = d.merge(
                self.issue(
                    case,
                    op_id,
                    now,
                    selected=with_clearance(self.td, ops, others, alt),
                    alternatives=[with_clearance(self.td, ops, others, x) for x in shown],
                    reason=f"{t.kind.value}: {alt.maneuver.value} (joint selection, "
                    f"score {sel.total:.3f})",
                )
            )
        return d

    # -- re-planning after a refusal
    def _replan(self, rec: Recommendation, snapshot: AirspaceSnapshot, why: str) -> Decision:
        """A new decision for the UAS of a refused (or expired) ``rec``, made as the last one
        was (:class:`~.decision.Mode`) without the refused manoeuvre; a refused command, or
        more than ``max_replans``, escalates."""
        now = snapshot.t_s
        case = self._cases.get(rec.threat_id)
        op_id = rec.operation_id
        if case is None:
            return Decision()
        n = case.replans.get(op_id, 0) + 1
        case.replans[op_id] = n
        if rec.selected is not None:
            case.excluded.setdefault(op_id, set()).add(rec.selected.maneuver)
        mode = case.modes.get(op_id)
        if mode is Mode.COMMAND:  # the pilot refused (or let expire) the command itself
            msg = f"{rec.threat_id}: {op_id} {why} a command; operator action needed"
            audit = self.audit(now, "escalation", rec.threat_id, {"reason": msg})
            return Decision(escalations=(msg,), audit=(audit,))
        if n > self.config.max_replans:  # escalate with a command to confirm
            msg = f"{rec.threat_id}: {op_id} {why} {n - 1} re-plans"
            return propose(self.ctx, case, snapshot, msg, [op_id], choose=mode is Mode.MULTI)
        if mode is Mode.MULTI:
            return self._multi(case, snapshot)
        if mode is Mode.INTRUDER:
            return intruder(self.ctx, case, op_id, snapshot)
        maneuvers = case.maneuvers.get(op_id, frozenset())
        threat = case.threat
        if op_id not in threat.uas_ids and case.geofences:
            threat = replace(
                threat, kind=ThreatKind.GEOFENCE_CONFLICT, uas_ids=(op_id,), area=case.geofences[-1]
            )
        return single(self.ctx, case, op_id, snapshot, maneuvers, threat=threat)
