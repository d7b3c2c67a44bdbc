"""A recommendation nobody answered before its deadline (``[emergency] expiry_action``).

Nobody at the keys is not a decision: the version is EXPIRED, escalated and audited, and
with ``expiry_action = "repropose"`` (the default) the UAS's *safe command* is proposed again
at once as a new version: for a loss of separation EM's immediate command (hold, climb or
descend in place, see :mod:`.immediate`), else the threat's safe command (hold, land, return
to launch: :func:`.supervision.safe_command`). When that one expires too, it is proposed
again, and so on while the threat is open: the operator keeps being asked, and nothing is
carried out without an answer (only ``autonomous = true`` does that). With ``"replan"`` EM
re-plans without the expired manoeuvre, as after a rejection (the safe command after
``max_replans``).

The audit entry ``expired`` (actor EM) says what follows: ``expiry_action`` and ``next``
(the re-proposed version and its command, or that a re-plan follows).
"""

from __future__ import annotations

from gcs_utm.core.emergency.config import ExpiryAction
from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Decision
from gcs_utm.core.emergency.immediate import propose
from gcs_utm.core.emergency.supervision import describe, escalate_safe
from gcs_utm.model import AirspaceSnapshot, Recommendation, RecommendationState, ThreatKind


def expire(
    em: EmContext, rec: Recommendation, snapshot: AirspaceSnapshot
) -> tuple[Decision, Recommendation | None]:
    """Mark ``rec`` EXPIRED (when it is still EM's pending version) with its escalation and
    audit; with ``repropose`` also propose the safe command again. Returns the decision and
    the expired version (None: nothing expired, a stale notice)."""
    now = snapshot.t_s
    cur = em.recommendation(rec.id)
    if cur is None or cur.version != rec.version or cur.state is not RecommendationState.PROPOSED:
        return Decision(), None
    new = em.record(
        cur.transition(RecommendationState.EXPIRED, now, "no answer before the deadline")
    )
    action = em.config.expiry_action
    msg = f"{rec.id} v{rec.version} ({rec.operation_id}) expired without an answer"
    again = Decision()
    nxt = "re-plan without the expired manoeuvre"
    if action == ExpiryAction.REPROPOSE:
        again = _repropose(em, new, snapshot, msg)
        mine = [r for r in again.recommendations if r.id == rec.id]
        nxt = (
            ", ".join(
                f"v{r.version} {describe(r.command) if r.command else 'plan'} proposed"
                for r in mine
            )
            or "nothing could be proposed"
        )
    detail = {"version": rec.version, "expiry_action": action, "next": nxt}
    d = Decision(
        recommendations=(new,),
        escalations=(msg,),
        audit=(em.audit(now, "expired", rec.id, detail),),
    )
    return d.merge(again), new


def _repropose(
    em: EmContext, rec: Recommendation, snapshot: AirspaceSnapshot, why: str
) -> Decision:
    """The safe command for the UAS of ``rec``, proposed as a new version."""
    case = em.case(rec.threat_id)
    if case is None:
        return Decision()
    op_id = rec.operation_id
    why = f"{why}: safe command proposed again"
    if case.threat.kind is ThreatKind.LOSS_OF_SEPARATION:
        d = propose(em, case, snapshot, why, [op_id])
        if any(r.operation_id == op_id and r.command is not None for r in d.recommendations):
            return d
    return escalate_safe(em, case, [op_id], snapshot.t_s, why)
