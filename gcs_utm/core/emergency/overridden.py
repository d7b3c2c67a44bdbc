"""A plan overtaken by a command: not uploaded over a newer command for the same UAS.

EM may decide two threats of one UAS in the same cycle: a plan for one (a conformance
case's way back to its plan, say) and, after it, an immediate command for a loss of
separation predicted a few seconds ahead. Both are accepted together; the USM sends the
command and then uploads the plan, and the autopilot flies the mission it was given last:
the plan, which was decided without the command and undoes it. A fixed wing sent back to
a point behind it turned round on its radius into the multirotor the command turned it
away from (``enc_3_0475_endpoint_crossing``: UAS2 past UAS3 at 23.9 m / 19.1 m against
50 / 40 m). So the re-check before an upload (:mod:`.recheck`) refuses a plan when another
open case holds a live command for the same UAS (proposed, accepted or applied) decided no
earlier than the plan: the newer decision stands. The refusal is not a failure of the
plan's case (:func:`overtaken`): re-planning at once would decide a plan after the command
and upload it over it after all, and proposing the case's safe command (a hold) would undo
the command just the same (``enc_5_0132_fence_overtaking``: a conformance case's way back
refused for a loss case's turn, then its hold sent over the turn; the held fixed wing passed
UAS6 at 41.3 m / 33.0 m against 50 / 40 m). The case waits ``retry_after_s``, as after an
escalation, and is then decided again on the snapshot of that time, with the command in
force. Pure.
"""

from __future__ import annotations

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.model import Recommendation, RecommendationState

_LIVE = (RecommendationState.PROPOSED, RecommendationState.ACCEPTED, RecommendationState.APPLIED)


def newer_command(em: EmContext, rec: Recommendation) -> str:
    """The id of another open case's live command recommendation for ``rec``'s UAS decided
    at or after ``rec`` ("" when there is none; see the module doc)."""
    for tid in em.open_threats():
        case = em.case(tid)
        if case is None or tid == rec.threat_id:
            continue
        for rid in sorted(case.rec_ids):
            r = em.recommendation(rid)
            if (
                r is not None
                and r.operation_id == rec.operation_id
                and r.command is not None
                and r.state in _LIVE
                and r.created_t_s >= rec.created_t_s
            ):
                return str(r.id)
    return ""


def overtaken(em: EmContext, case: Case, rec: Recommendation, now: float) -> Decision | None:
    """After ``rec``'s upload failed: when a newer command of another case stands for its UAS,
    the case neither re-plans nor proposes its safe command; it is retried after
    ``retry_after_s`` (see the module doc). None when no such command stands."""
    newer = newer_command(em, rec)
    if not newer:
        return None
    case.attempt_t_s = now  # the retry of a case with nothing in force waits from here
    why = f"{rec.id} v{rec.version} overtaken by the command of {newer}: it stands"
    return Decision(audit=(em.audit(now, "overtaken", case.threat.id, {"reason": why}),))
