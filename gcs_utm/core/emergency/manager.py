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
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from dataclasses import replace

from gcs_utm.core.deconfliction import TacticalDeconfliction
from gcs_utm.core.emergency.clearance import with_clearance
from gcs_utm.core.emergency.config import EmergencyConfig
from gcs_utm.core.emergency.decision import (
    ACTOR,
    MODE_COMMAND,
    MODE_INTRUDER,
    MODE_MULTI,
    ONE_SHOT,
    SINGLE_MANEUVERS,
    Case,
    Decision,
)
from gcs_utm.core.emergency.expiry import expire
from gcs_utm.core.emergency.geofences import area, link_loss, suspend
from gcs_utm.core.emergency.immediate import held_by, keep_all, late_reason, propose
from gcs_utm.core.emergency.lead import ResponseTimes
from gcs_utm.core.emergency.selection import (
    STAY_DETAIL,
    Selection,
    TieredSelection,
    is_stay,
    select_by_priority,
    stay,
    weighted,
)
from gcs_utm.core.emergency.supervision import (
    deviation_start,
    escalate_safe,
    on_outcome,
    safe_command,
    settled_at,
    supervise_case,
)
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    AuditEntry,
    Command,
    CommandKind,
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
    "a UAS is not where its plan says; immediate command proposed"
)
"""Why a multi-UAS decision that moves nobody moves nobody (``all_kept`` in its audit)."""


def _alt_record(alt: Alternative, alpha: float, beta: float) -> dict[str, object]:
    return {
        "operation_id": alt.operation_id,
        "maneuver": alt.maneuver.value,
        "cost": round(alt.cost, 6),
        "risk": round(alt.risk, 6),
        "score": round(weighted(alt, alpha, beta), 6),
        "detail": alt.detail,
        "waypoints": 0 if alt.plan is None else len(alt.plan.waypoints),
    }


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

    # ---- queries ----------------------------------------------------------------------------
    def pending(self) -> list[Recommendation]:
        """Recommendations waiting for an answer, earliest deadline first."""
        recs = [r for r in self._recs.values() if r.state is RecommendationState.PROPOSED]
        return sorted(recs, key=lambda r: r.deadline_t_s)

    def recommendation(self, rec_id: RecommendationId) -> Recommendation | None:
        return self._recs.get(rec_id)

    def open_threats(self) -> list[ThreatId]:
        return list(self._cases)

    def case(self, threat_id: ThreatId) -> Case | None:
        return self._cases.get(threat_id)

    def adopt(self, case: Case) -> None:  # a previous life's case, as it is (see .adoption)
        self._cases[case.threat.id] = case

    def record(self, rec: Recommendation) -> Recommendation:
        """Store ``rec`` as the current version of its id; returns it."""
        self._recs[rec.id] = rec
        return rec

    def forget_operations(self, op_ids: Collection[OperationId]) -> None:
        """Operations the airspace forgot (services/retention.py): their recommendations leave
        memory, except one an open case still refers to (the store keeps the record)."""
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
        if case.action in ONE_SHOT or self._pending(case):
            return Decision()
        if self._in_force(case):
            return supervise_case(self, case, snapshot)
        if snapshot.t_s - case.attempt_t_s < self.config.retry_after_s:
            return Decision()
        case.attempt_t_s = snapshot.t_s
        case.replans.clear()
        return self._handle(case, snapshot)

    def supervising(self) -> bool:
        """Is any open case waiting on an accepted plan or on a retry after an escalation
        (so :meth:`supervise` has work)?"""
        return any(c.action not in ONE_SHOT and not self._pending(c) for c in self._cases.values())

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
        return on_outcome(self, rec_id, version, applied, reason, snapshot)

    def decide_again(self, case: Case, snapshot: AirspaceSnapshot) -> Decision:
        """A fresh decision for an open case on the current snapshot (new versions)."""
        return self._handle(case, snapshot)

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
        d, new = expire(self, rec, snapshot)
        if new is None or self.config.expiry_action != "replan":
            return d
        return d.merge(self._replan(new, snapshot, "expired"))

    def on_threat_closed(self, threat: Threat) -> Decision:
        case = self._cases.pop(threat.id, None)
        if case is None:
            return Decision()
        t = threat.updated_at_s if threat.updated_at_s is not None else threat.detected_at_s
        recs: list[Recommendation] = []
        for rid in sorted(case.rec_ids):
            cur = self._recs[rid]
            if cur.state is RecommendationState.PROPOSED:
                new = cur.transition(RecommendationState.SUPERSEDED, t, "threat closed")
                self._recs[rid] = new
                recs.append(new)
        return Decision(
            recommendations=tuple(recs),
            superseded=tuple(r.id for r in recs),
            audit=(
                self.audit(t, "threat_closed", threat.id, {"superseded": [r.id for r in recs]}),
            ),
        )

    # ---- internals --------------------------------------------------------------------------
    def _intended(self, snapshot: AirspaceSnapshot, case: Case) -> AirspaceSnapshot:
        """``snapshot`` with every plan another case has recommended and that is not in the
        airspace yet (proposed or accepted) in place of the UAS's plan: overlapping threats
        decided one after the other build on each other's plans (three pairwise threats
        among three UAS, each decided on the filed plans, gave two of them plans that met)."""
        live = (RecommendationState.PROPOSED, RecommendationState.ACCEPTED)
        latest: dict[OperationId, Recommendation] = {}
        for r in self._recs.values():
            if r.threat_id == case.threat.id or r.state not in live:
                continue
            if r.selected is None or r.selected.plan is None:
                continue
            prev = latest.get(r.operation_id)
            if prev is None or r.created_t_s >= prev.created_t_s:
                latest[r.operation_id] = r
        ops = snapshot.operations
        # An accepted plan the airspace already holds (or a newer one: uploads stamp the plan
        # they install with their time) is not replaced; the outcome may not be reported.
        changed = {
            k: replace(ops[k], plan=replace(r.selected.plan, operation_id=k))
            for k, r in latest.items()
            if k in ops
            and r.selected is not None
            and r.selected.plan is not None
            and ops[k].plan.created_t_s < r.created_t_s
        }
        if not changed:
            return snapshot
        return replace(snapshot, operations={**ops, **changed})

    def _pending(self, case: Case) -> bool:
        return any(self._recs[r].state is RecommendationState.PROPOSED for r in case.rec_ids)

    def _in_force(self, case: Case) -> bool:
        force = (RecommendationState.ACCEPTED, RecommendationState.APPLIED)
        return any(self._recs[r].state in force for r in case.rec_ids)

    def plan_start(self, threat: Threat, now: float) -> float:
        """When a plan decided now can start: the expected answer (none in autonomous mode;
        measured per vehicle, else the automatic operator's delay or ``expected_answer_s``,
        never past the deadline), the upload and a margin (see .lead). The vehicle has the
        plan before then, and its first waypoint lies ahead of it."""
        return self.lead.plan_start(threat.uas_ids, now, self._deadline(threat, now))

    def supervision_due(self, rec: Recommendation) -> float | None:
        """When an accepted ``rec`` is settled (see :mod:`.supervision`); None when its case
        is closed."""
        case = self._cases.get(rec.threat_id)
        return None if case is None else settled_at(self, case, rec)

    def manoeuvre_start(self, rec: Recommendation) -> float:
        """When the plan of ``rec`` leaves the UAS's path (its lead-in ends)."""
        return self.lead.plan_start((rec.operation_id,), rec.created_t_s, rec.deadline_t_s)

    def earliest_receipt(self, now: float, op_ids: Sequence[OperationId] = ()) -> float:
        """The earliest the vehicle can have a plan decided now: an immediate answer (or the
        automatic operator's delay) plus the upload. A new plan carries timed points of the
        current path from then to its start (TD's lead-in)."""
        return self.lead.earliest_receipt(op_ids, now)

    def audit(self, t_s: float, action: str, subject: str, detail: dict[str, object]) -> AuditEntry:
        return AuditEntry(t_s=t_s, actor=ACTOR, action=action, subject=str(subject), detail=detail)

    def _deadline(self, threat: Threat, now: float) -> float:
        event = threat.predicted_event_at_s
        if event is None:
            event = now + self.config.default_event_horizon_s
        cfg = self.config
        latest = now + max(cfg.min_response_s, cfg.answer_window_s)
        return min(latest, max(now + cfg.min_response_s, event - cfg.deadline_margin_s))

    def issue(
        self,
        case: Case,
        op_id: OperationId,
        now: float,
        *,
        selected: Alternative | None = None,
        command: Command | None = None,
        alternatives: Sequence[Alternative] = (),
        reason: str,
        geofence: Geofence | None = None,
    ) -> Decision:
        """A new recommendation (or a new version replacing a pending one)."""
        rid = RecommendationId(f"{case.threat.id}/{op_id}")
        prev = self._recs.get(rid)
        superseded: list[RecommendationId] = []
        recs: list[Recommendation] = []
        if prev is not None and prev.state is RecommendationState.PROPOSED:
            old = prev.transition(RecommendationState.SUPERSEDED, now, "replaced by a new version")
            recs.append(old)
            superseded.append(rid)
        op = case.operations.get(op_id)
        if selected is not None and selected.plan is not None and op is not None:
            t_dev = deviation_start(self.frame, selected.plan, op.plan, op.flight_geometry_m)
            if t_dev is not None:
                case.deviates_at[rid] = t_dev
        rec = Recommendation(
            id=rid,
            version=max(0 if prev is None else prev.version, self._floors.get(rid, 0)) + 1,
            threat_id=case.threat.id,
            threat_kind=case.threat.kind,
            operation_id=op_id,
            created_t_s=now,
            deadline_t_s=self._deadline(case.threat, now),
            selected=selected,
            command=command,
            alternatives=tuple(alternatives),
            reason=reason,
            new_geofence=geofence,
            state_t_s=now,
        )
        commands: tuple[Command, ...] = ()
        if self.config.autonomous:
            rec = rec.transition(RecommendationState.ACCEPTED, now, "autonomous mode")
            if command is not None:
                commands = (command,)
        self._recs[rid] = rec
        case.rec_ids.add(rid)
        recs.append(rec)
        return Decision(
            recommendations=tuple(recs), superseded=tuple(superseded), commands=commands
        )

    def _handle(self, case: Case, snapshot: AirspaceSnapshot) -> Decision:
        t = case.threat
        a = case.action
        if a == "alternative_plans":
            return self._multi(case, snapshot)
        if a == "warn":
            msg = f"{t.kind.value}: {', '.join(t.uas_ids)} {t.message}".strip()
            return Decision(
                warnings=(msg,), audit=(self.audit(snapshot.t_s, "warn", t.id, {"message": msg}),)
            )
        geofencing = {
            "suspend_and_geofence": suspend,
            "alert_and_geofence": link_loss,
            "geofence_from_area": area,
        }
        if a in geofencing:
            return geofencing[a](self, case, snapshot)
        # one decision per UAS of the threat
        if a in SINGLE_MANEUVERS:
            maneuvers = SINGLE_MANEUVERS[a]

            def per_uas(op_id: OperationId) -> Decision:
                return self.single(case, op_id, snapshot, maneuvers)

        elif a == "vertical_avoidance":

            def per_uas(op_id: OperationId) -> Decision:
                return self._intruder(case, op_id, snapshot)

        else:
            raise AssertionError(f"unhandled action {a!r}")  # EmergencyConfig validates actions
        d = Decision()
        for op_id in t.uas_ids:
            d = d.merge(per_uas(op_id))
        return d

    # -- multi-UAS
    def _multi(self, case: Case, snapshot: AirspaceSnapshot) -> Decision:
        """Charged cords + joint selection under the priority rule (selection tiers). A UAS
        without a verified option stays on its plan (escalated for it) while the others
        move. An immediate command is proposed (.immediate) when the event is nearer than a
        new plan's start, when no combination resolves the conflict, or when every plan
        (re-timed from the vehicles' progress by the snapshot provider) is kept."""
        snapshot = self._intended(snapshot, case)
        case.operations = dict(snapshot.operations)
        now = snapshot.t_s
        t = case.threat
        late = late_reason(self, case, snapshot)  # with plans in force: only if they change
        if late and not self._in_force(case):
            return propose(self, case, snapshot, late, t.uas_ids)
        options, tiered, compatible = self._joint(case, snapshot, buffered=True)
        if tiered is None:
            # No combination keeps the vehicles' tracking tolerances free: the best one that
            # keeps the bare minima beats no decision at all.
            options, tiered, compatible = self._joint(case, snapshot, buffered=False)
        sel = None if tiered is None else tiered.selection
        detail = self._detail(options, sel, "loss of separation: charged cords + joint selection")
        if tiered is None:
            msg = f"{t.id}: no conflict-free combination of alternatives for {', '.join(t.uas_ids)}"
            audit = Decision(audit=(self.audit(now, "escalation", t.id, detail),))
            return audit.merge(propose(self, case, snapshot, msg, t.uas_ids))
        detail["moved_up_to_priority"] = tiered.moved_up_to_priority
        kept = all(a.maneuver is Maneuver.KEEP_PLAN for a in tiered.selection.chosen.values())
        if kept:
            detail["all_kept"] = KEPT_REASON
        d = Decision(audit=(self.audit(now, "decision", t.id, detail),))
        if late and not kept:
            return d.merge(propose(self, case, snapshot, late, t.uas_ids))
        d = d.merge(self._issue_joint(case, tiered.selection, options, compatible, now))
        if kept and not self._in_force(case):
            d = d.merge(keep_all(self, case, snapshot))  # never keep all: see .immediate
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
            case.modes[op_id] = MODE_MULTI
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

    def _detail(
        self,
        options: dict[OperationId, list[Alternative]],
        sel: Selection | None,
        reason: str,
    ) -> dict[str, object]:
        cfg = self.config
        return {
            "reason": reason,
            "alpha": cfg.alpha,
            "beta": cfg.beta,
            "alternatives": [
                _alt_record(x, cfg.alpha, cfg.beta) for alts in options.values() for x in alts
            ],
            "selected": None
            if sel is None
            else {k: v.maneuver.value for k, v in sel.chosen.items()},
            "total": None if sel is None else round(sel.total, 6),
            "explored": None if sel is None else sel.explored,
            "truncated": None if sel is None else sel.truncated,
            "dropped": [
                {"operation_id": x.operation_id, "maneuver": x.maneuver.value, "reason": x.reason}
                for x in self.td.dropped
            ],
        }

    # -- single UAS
    def single(
        self,
        case: Case,
        op_id: OperationId,
        snapshot: AirspaceSnapshot,
        maneuvers: frozenset[Maneuver],
        threat: Threat | None = None,
    ) -> Decision:
        now = snapshot.t_s
        t = threat or case.threat
        held = held_by(self, op_id, case) if case.action == "back_to_plan" else None
        if held:  # off its plan on purpose: not sent back into the loss it avoids
            why: dict[str, object] = {"reason": f"{op_id} follows {held}'s immediate command"}
            return Decision(audit=(self.audit(now, "deferred", case.threat.id, why),))
        snapshot = self._intended(snapshot, case)
        case.operations = dict(snapshot.operations)
        case.modes[op_id] = f"single:{','.join(sorted(m.value for m in maneuvers))}"
        allowed = maneuvers - case.excluded.get(op_id, set())
        alts = self.td.resolve_single(
            t,
            op_id,
            snapshot,
            maneuvers=allowed,
            extra_geofences=tuple(case.geofences),
            start_t_s=self.plan_start(t, now),
            lead_in_from_t_s=self.earliest_receipt(now, (op_id,)),
        )
        cfg = self.config
        if case.action == "land_or_home":
            # Energy first: with the battery or the vehicle failing, the option that is on the
            # ground soonest wins; the weighted score only breaks ties.
            alts.sort(
                key=lambda x: (
                    x.plan.end_t_s if x.plan is not None else now,
                    weighted(x, cfg.alpha, cfg.beta),
                )
            )
        else:
            alts.sort(key=lambda x: weighted(x, cfg.alpha, cfg.beta))
        options = {op_id: alts}
        best = alts[0] if alts else None
        sel = (
            None
            if best is None
            else Selection(
                chosen={op_id: best},
                total=weighted(best, cfg.alpha, cfg.beta),
                explored=len(alts),
                truncated=False,
            )
        )
        detail = self._detail(options, sel, f"{t.kind.value}: {case.action}")
        if best is None:
            audit = (self.audit(now, "escalation", case.threat.id, detail),)
            if case.action == "land_or_home":
                # Low battery or failure and no reachable site: land where it is, and say so.
                cmd = Command(kind=CommandKind.LAND, operation_id=op_id)
                case.modes[op_id] = MODE_COMMAND
                msg = f"{case.threat.id}: no reachable landing site or home for {op_id}: land now"
                d = self.issue(case, op_id, now, command=cmd, reason=msg)
                return d.merge(Decision(escalations=(msg,), audit=audit))
            msg = f"{case.threat.id}: no feasible alternative for {op_id} ({t.kind.value})"
            return Decision(audit=audit).merge(escalate_safe(self, case, [op_id], now, msg))
        d = Decision(audit=(self.audit(now, "decision", case.threat.id, detail),))
        return d.merge(
            self.issue(
                case,
                op_id,
                now,
                selected=best,
                alternatives=alts[1:],
                reason=f"{t.kind.value}: {best.maneuver.value}",
            )
        )

    def _intruder(self, case: Case, op_id: OperationId, snapshot: AirspaceSnapshot) -> Decision:
        snapshot = self._intended(snapshot, case)
        case.operations = dict(snapshot.operations)
        now = snapshot.t_s
        cfg = self.config
        case.modes[op_id] = MODE_INTRUDER
        banned = case.excluded.get(op_id, set())
        alts = [
            x
            for x in self.td.resolve_intruder(
                case.threat,
                op_id,
                snapshot,
                self.plan_start(case.threat, now),
                self.earliest_receipt(now, (op_id,)),
            )
            if x.maneuver not in banned
        ]
        alts.sort(key=lambda x: weighted(x, cfg.alpha, cfg.beta))
        sel = (
            None
            if not alts
            else Selection(
                chosen={op_id: alts[0]},
                total=weighted(alts[0], cfg.alpha, cfg.beta),
                explored=len(alts),
                truncated=False,
            )
        )
        detail = self._detail({op_id: alts}, sel, "intruder: avoidance")
        if not alts:
            # Nothing flyable keeps the minima: propose the safe command (hold) and escalate.
            cmd = Command(kind=safe_command(case.threat.kind), operation_id=op_id)
            case.modes[op_id] = MODE_COMMAND
            msg = (
                f"{case.threat.id}: no avoidance for {op_id} from intruder "
                f"{case.threat.intruder_id}: {cmd.kind.value} proposed"
            )
            audit = (self.audit(now, "escalation", case.threat.id, detail),)
            d = self.issue(case, op_id, now, command=cmd, reason=msg)
            return d.merge(Decision(escalations=(msg,), audit=audit))
        d = Decision(audit=(self.audit(now, "decision", case.threat.id, detail),))
        return d.merge(
            self.issue(
                case,
                op_id,
                now,
                selected=alts[0],
                alternatives=alts[1:],
                reason=f"intruder {case.threat.intruder_id}: {alts[0].maneuver.value}",
            )
        )

    # -- re-planning after a refusal
    def _replan(self, rec: Recommendation, snapshot: AirspaceSnapshot, why: str) -> Decision:
        now = snapshot.t_s
        case = self._cases.get(rec.threat_id)
        op_id = rec.operation_id
        if case is None:
            return Decision()
        n = case.replans.get(op_id, 0) + 1
        case.replans[op_id] = n
        if rec.selected is not None:
            case.excluded.setdefault(op_id, set()).add(rec.selected.maneuver)
        mode = case.modes.get(op_id, "")
        if mode == MODE_COMMAND:  # the pilot refused (or let expire) the command itself
            msg = f"{rec.threat_id}: {op_id} {why} a command; operator action needed"
            audit = self.audit(now, "escalation", rec.threat_id, {"reason": msg})
            return Decision(escalations=(msg,), audit=(audit,))
        if n > self.config.max_replans:  # escalate with a command to confirm
            msg = f"{rec.threat_id}: {op_id} {why} {n - 1} re-plans"
            return propose(self, case, snapshot, msg, [op_id], choose=mode == MODE_MULTI)
        if mode == MODE_MULTI:
            return self._multi(case, snapshot)
        if mode == MODE_INTRUDER:
            return self._intruder(case, op_id, snapshot)
        maneuvers = frozenset(Maneuver(v) for v in mode.removeprefix("single:").split(",") if v)
        threat = case.threat
        if op_id not in threat.uas_ids and case.geofences:
            threat = replace(
                threat, kind=ThreatKind.GEOFENCE_CONFLICT, uas_ids=(op_id,), area=case.geofences[-1]
            )
        return self.single(case, op_id, snapshot, maneuvers, threat=threat)
