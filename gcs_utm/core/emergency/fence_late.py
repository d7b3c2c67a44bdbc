"""A geofence entry nearer than a new plan can start gets an immediate command.

A new plan acts only once it is answered, uploaded and started (:mod:`.lead`); until then the
vehicle flies on where it was going. When Monitoring predicts a UAS entering a geofence
sooner than that, every plan TD can offer starts where the UAS will be: inside the fence
(``enc_5_0036_fence_head_on``: a multirotor at 6.1 m/s, the entry predicted 4.1 s ahead,
the plan's start 5 s ahead; TD's return home started 5.7 m inside, its leg out unverified as
from inside a fence, and the UAS flew 4.2 s inside). A command acts after the answer and its
acknowledgement, with no upload: a multirotor brakes and stops short of the fence.

So for a geofence conflict whose entry is nearer than a new plan's start, the immediate
commands of the UAS alone (:func:`.immediate.choose_commands`: hold, climb or descend in
place, a fixed wing's turns, each flown against the other traffic and checked against the
fences grown by the UAS's volume) are tried first: the best one that keeps the minima is
proposed, for a fixed wing only when it enters no fence (a fixed wing cannot stop; a plan may
still turn it away sooner), for a multirotor even when its stopping point lies within the
fence's grown volume (braking now is the shortest way to stop; the next decision leads it
out). The plans are tried when no command qualifies. Pure."""

from __future__ import annotations

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.core.emergency.immediate import commands_now
from gcs_utm.core.emergency.supervision import escalate_safe
from gcs_utm.model import AirspaceSnapshot, OperationId, Threat, ThreatKind


def late_entry(em: EmContext, threat: Threat, now: float) -> str:
    """Why a new plan decided ``now`` would start after the predicted geofence entry of
    ``threat`` ("" when it would not, or the threat is not a geofence conflict). An entry
    time already past is not late but stale: the UAS stopped short of the fence under the
    command (the threat keeps the time it was first reported with), and plans lead it out."""
    event = threat.predicted_event_at_s
    if threat.kind is not ThreatKind.GEOFENCE_CONFLICT or event is None or event < now:
        return ""
    lead_s = em.plan_start(threat, now) - now
    if event - now >= lead_s:
        return ""
    return (
        f"{threat.id}: entry into {threat.geofence_id or 'a geofence'} predicted in "
        f"{event - now:.1f} s, sooner than a new plan can start ({lead_s:.1f} s: answer, "
        "upload, margin)"
    )


def fence_command(
    em: EmContext, case: Case, op_id: OperationId, snapshot: AirspaceSnapshot, threat: Threat
) -> Decision | None:
    """The immediate command proposed to ``op_id`` (with an escalation that names it) for a
    geofence entry nearer than a new plan's start, or None: not such a conflict, or no
    command that keeps the minima (and, for a fixed wing, enters no fence)."""
    now = snapshot.t_s
    if threat is not case.threat:  # derived (a UAS a new fence blocks): no entry time
        return None
    why = late_entry(em, threat, now)
    op = snapshot.operations.get(op_id)
    if not why or op is None:
        return None
    choice = commands_now(em, snapshot, [op_id], threat.predicted_event_at_s)
    if choice is None or not choice.commands or not choice.clear:
        return None
    if choice.geofences and not op.performance().can_hover:
        return None
    text = f"{why}; immediate command keeps the minima (ratio {choice.ratio:.2f})"
    detail: dict[str, object] = {"reason": text, "selected": choice.actions}
    detail["tried"] = choice.tried
    detail["acts_in_s"] = round(em.lead.command_at([op_id], now) - now, 3)
    audit = Decision(audit=(em.audit(now, "immediate", case.threat.id, detail),))
    return audit.merge(
        escalate_safe(em, case, list(choice.commands), now, text, choice.commands, choice.actions)
    )
