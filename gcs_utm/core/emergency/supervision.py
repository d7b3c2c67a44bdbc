"""Supervision of what was decided: a threat that stays open after its plan was applied, and
an upload that failed, each lead to a new decision (paper §4.4: nothing is dropped).

- **Persisting threat.** A recommendation accepted (and, when the service reports it,
  applied) is *settled* ``supervision_grace_s`` after its plan leaves the plan it replaces
  by more than the flight geometry (a deformation ramps away only where it is needed, and a
  predictor that extrapolates the track sees the conflict until the UAS turns), and never
  before the plan started (for a command: once it was accepted, plus the upload time and
  the grace). When every
  accepted recommendation of a case is settled and Monitoring still reports the threat (the
  case is open: Monitoring closes a threat only after it cleared for ``close_cycles``), EM
  decides again on the current snapshot (which holds the applied plans): a new version of
  the recommendation, up to ``max_replans`` times; then it escalates with the reason,
  proposing the threat's safe command. When the new decision keeps the standing plans (it
  chooses them again) nothing is sent; when it finds no combination at all it escalates
  likewise. Further supervision of the case waits ``retry_after_s``. Once a *final* safe
  command (land, return to launch) is in force for every UAS of the case, the threat is
  expected to stay open until the UAS is down or home (a degraded GNSS does not recover by
  landing), so the same command is not proposed again every ``retry_after_s``: the pilot
  would be asked the same question over and over while the vehicle already does it. That is
  audited once; a vehicle that does not comply is Monitoring's business (conformance).
- **Failed upload or verification.** The first failure for a UAS re-plans once; the next
  escalates and proposes the safe command for the threat kind (:func:`safe_command`): the
  UAS is never left with a failed plan and no pending decision. A plan refused before its
  upload for a newer command of another case for the same UAS is not a failure: the command
  stands and the case is retried after ``retry_after_s`` (:mod:`.overridden`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import ONE_SHOT, Case, Decision, Mode
from gcs_utm.core.emergency.overridden import overtaken
from gcs_utm.core.emergency.supervision_due import retry_wait_s
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatKind,
)

_LAND_KINDS = frozenset(
    {ThreatKind.LACK_OF_BATTERY, ThreatKind.TECHNICAL_FAILURE, ThreatKind.GNSS_DEGRADATION}
)
_RTL_KINDS = frozenset({ThreatKind.COMMUNICATION_FAILURE})
_IN_FORCE = (RecommendationState.ACCEPTED, RecommendationState.APPLIED)
_FINAL_COMMANDS = frozenset({CommandKind.LAND, CommandKind.RTL})
"""Safe commands after which nothing better can be proposed for the UAS."""


def safe_command(kind: ThreatKind) -> CommandKind:
    """The command that keeps a UAS safe when no plan can be flown: land when energy or the
    vehicle is failing, return to launch when the link is, else hold (a multirotor holds
    position, a fixed wing loiters: the autopilot mapping does that)."""
    if kind in _LAND_KINDS:
        return CommandKind.LAND
    if kind in _RTL_KINDS:
        return CommandKind.RTL
    return CommandKind.HOLD


def settled_at(em: EmContext, case: Case, rec: Recommendation) -> float:
    """When an accepted or applied recommendation should show its effect on the threat."""
    cfg = em.config
    t = rec.state_t_s if rec.state_t_s is not None else rec.created_t_s
    if rec.state is RecommendationState.ACCEPTED:
        t += cfg.upload_time_s  # the service may not report the outcome
    if rec.selected is not None and rec.selected.plan is not None:
        t = max(t, em.manoeuvre_start(rec), case.deviates_at.get(rec.id, -np.inf))
    return t + cfg.supervision_grace_s


def supervise_case(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision:
    """A new decision when the case's accepted plans are settled and the threat persists."""
    now = snapshot.t_s
    recs = [em.recommendation(r) for r in sorted(case.rec_ids)]
    live = [r for r in recs if r is not None and r.state in _IN_FORCE]
    if _not_due(em, case, recs, live, now):
        return Decision()
    if _final_command_in_force(case, live):
        return _final_noted(em, case, live, now)
    case.supervised += 1
    case.attempt_t_s = now
    versions = ", ".join(f"{r.id} v{r.version}" for r in live)
    why = f"{case.threat.id} ({case.threat.kind.value}) still predicted after {versions}"
    if case.supervised > em.config.max_replans:
        return escalate_safe(em, case, [r.operation_id for r in live], now, why)
    d = em.decide(case, snapshot)
    audit = em.audit(now, "supervision", case.threat.id, {"reason": why})
    if d.escalations and not d.recommendations:
        return d.merge(escalate_safe(em, case, [r.operation_id for r in live], now, why))
    return Decision(audit=(audit,)).merge(d)


def _not_due(
    em: EmContext,
    case: Case,
    recs: list[Recommendation | None],
    live: list[Recommendation],
    now: float,
) -> bool:
    """Nothing to supervise yet: a one-shot action, nothing in force, a pilot still asked, a
    plan not settled, or the last attempt less than ``retry_after_s`` ago (less when the
    predicted event comes sooner: :mod:`.supervision_due`)."""
    if case.action in ONE_SHOT or not live:
        return True
    if any(r is not None and r.state is RecommendationState.PROPOSED for r in recs):
        return True
    if now < max(settled_at(em, case, r) for r in live):
        return True
    return bool(case.supervised) and now - case.attempt_t_s < retry_wait_s(em, case, now)


def _final_noted(em: EmContext, case: Case, live: list[Recommendation], now: float) -> Decision:
    """Audit once that the final safe command stays in force and is not proposed again."""
    if case.final_in_force:
        return Decision()
    case.final_in_force = True
    commands = ", ".join(f"{r.id} v{r.version}" for r in live)
    why = f"final safe command in force ({commands}): not proposed again"
    return Decision(audit=(em.audit(now, "supervision", case.threat.id, {"reason": why}),))


def _final_command_in_force(case: Case, live: list[Recommendation]) -> bool:
    """Every UAS of the case has a final safe command (land, RTL) accepted or applied."""
    kind = safe_command(case.threat.kind)
    return kind in _FINAL_COMMANDS and all(
        r.command is not None and r.command.kind is kind for r in live
    )


def escalate_safe(  # noqa: PLR0917 - the decision's context, then what to propose
    em: EmContext,
    case: Case,
    op_ids: list[OperationId],
    now: float,
    why: str,
    commands: Mapping[OperationId, Command] | None = None,
    actions: Mapping[OperationId, str] | None = None,
) -> Decision:
    """Escalate with ``why`` and propose a safe command to each UAS in ``op_ids``: the one in
    ``commands`` (EM's immediate command, see .immediate, with its ``actions`` named), else
    the threat's safe command."""
    kind = safe_command(case.threat.kind)
    cmds = {k: Command(kind=kind, operation_id=k) for k in dict.fromkeys(op_ids)}
    cmds.update(commands or {})
    acts = actions or {}
    what = (
        kind.value
        if not commands
        else ", ".join(f"{describe(c, acts.get(k, ''))} for {k}" for k, c in cmds.items())
    )
    msg = f"{why}; operator action needed: {what} proposed"
    d = Decision(
        escalations=(msg,),
        audit=(em.audit(now, "escalation", case.threat.id, {"reason": msg}),),
    )
    for op_id, cmd in cmds.items():
        case.modes[op_id] = Mode.COMMAND
        d = d.merge(em.issue(case, op_id, now, command=cmd, reason=msg))
    return d


def describe(cmd: Command, action: str = "") -> str:
    """A command in words: its kind, and a GOTO's target altitude with what the vehicle does
    to get there when the immediate command's ``action`` (.immediate) says it: climb or
    descend in place (a fixed wing circles there), turn left or right towards a point far
    abeam and fly on, climbing or descending or not, or climb or descend flying straight on
    (.turn). Without it a GOTO is named by its altitude alone."""
    if cmd.kind is not CommandKind.GOTO or cmd.target is None:
        return cmd.kind.value
    alt = f"{cmd.target.alt_amsl_m:.1f} m AMSL"
    if action in {"turn left", "turn right"}:
        return f"{action} towards a point far abeam, flying on at {alt}"
    if action.startswith("turn "):  # and climb, and descend
        return f"{action} to {alt} towards a point far abeam"
    if action.endswith(" ahead"):  # a fixed wing's climb or descent flying straight on
        return f"{action.removesuffix(' ahead')} to {alt} flying straight on"
    if action in {"climb", "descend"}:
        return f"{action} in place to {alt}"
    return f"goto {alt}"


def _plain_safe(
    em: EmContext, case: Case, op_ids: Sequence[OperationId], snapshot: AirspaceSnapshot, why: str
) -> Decision:
    return escalate_safe(em, case, list(op_ids), snapshot.t_s, why)


SafeAfterFailure = Callable[
    [EmContext, Case, Sequence[OperationId], AirspaceSnapshot, str], Decision
]
"""Escalates a UAS whose plan failed twice with what it proposes (.failed_safe)."""


def on_outcome(  # noqa: PLR0917 - the service's report, positional like on_answer
    em: EmContext,
    rec_id: RecommendationId,
    version: int,
    applied: bool,
    reason: str,
    snapshot: AirspaceSnapshot,
    safe: SafeAfterFailure = _plain_safe,
) -> Decision:
    """The service reports whether an accepted recommendation was applied (verified) or
    failed: record it; after a failure re-plan once, then escalate with the safe command."""
    now = snapshot.t_s
    cur = em.recommendation(rec_id)
    if cur is None or cur.version != version or cur.state is not RecommendationState.ACCEPTED:
        return Decision()
    state = RecommendationState.APPLIED if applied else RecommendationState.FAILED
    new = em.record(cur.transition(state, now, reason))
    d = Decision(
        recommendations=(new,),
        audit=(em.audit(now, state.value, rec_id, {"version": version, "reason": reason}),),
    )
    case = em.case(new.threat_id)
    if applied or case is None:
        return d
    waiting = overtaken(em, case, new, now)  # a newer command of another case stands
    if waiting is not None:
        return d.merge(waiting)
    op_id = new.operation_id
    n = case.failures.get(op_id, 0) + 1
    case.failures[op_id] = n
    why = f"{rec_id} v{version} for {op_id} failed ({reason})"
    if new.command is not None and case.modes.get(op_id) == Mode.COMMAND:
        # The safe command itself failed (e.g. the link is down): proposing it again would
        # only fail again, in a loop; the escalation leaves the decision to the operator.
        msg = f"{why}; the safe command failed too: operator action needed"
        audit = em.audit(now, "escalation", case.threat.id, {"reason": msg})
        return d.merge(Decision(escalations=(msg,), audit=(audit,)))
    if n > 1 or case.modes.get(op_id) == Mode.COMMAND:
        return d.merge(safe(em, case, [op_id], snapshot, why))
    again = em.decide(case, snapshot)
    mine = [r for r in again.recommendations if r.operation_id == op_id]
    if not any(r.state in (RecommendationState.PROPOSED, *_IN_FORCE) for r in mine):
        again = again.merge(safe(em, case, [op_id], snapshot, why))
    audit = em.audit(now, "replan_after_failure", case.threat.id, {"reason": why})
    return d.merge(Decision(audit=(audit,))).merge(again)
