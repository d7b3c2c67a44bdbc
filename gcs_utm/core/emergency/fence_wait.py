"""A predicted geofence entry with no feasible alternative yet: wait before the safe command.

With no verified alternative for a GEOFENCE_CONFLICT, EM escalated at once with the threat's
safe command (hold), however far ahead the entry was. A fixed wing cannot stop: held, it
circles where it is, and one held 60 s before a fence round its destination circled into a
multirotor (enc_1_0036_fence_head_on), while a reroute that ended outside the fence was
refused only because other UAS were near its path at that moment. Now, while the entry is
further ahead than the lead a new plan needs plus :data:`~.immediate.IMMINENT_S`, EM warns,
proposes nothing, and decides the case again within :data:`RETRY_S` (traffic moves, and a
path may open); from then on the safe command is proposed as before. Every other threat
kind escalates at once. Pure."""

from __future__ import annotations

from typing import TYPE_CHECKING

from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.core.emergency.immediate import IMMINENT_S
from gcs_utm.core.emergency.supervision import escalate_safe
from gcs_utm.model import OperationId, ThreatKind

if TYPE_CHECKING:
    from gcs_utm.core.emergency.manager import EmergencyManager

RETRY_S = 10.0
"""A deferred case is decided again at least this often."""


def no_alternative(
    em: EmergencyManager, case: Case, op_ids: list[OperationId], now: float, why: str
) -> Decision:
    """Escalate with the safe command (:func:`~.supervision.escalate_safe`), or for a
    geofence entry still far ahead, warn and decide again later (see the module doc)."""
    t = case.threat
    event = t.predicted_event_at_s
    if t.kind is not ThreatKind.GEOFENCE_CONFLICT or event is None:
        return escalate_safe(em, case, op_ids, now, why)
    due_t_s = event - (em.plan_start(t, now) - now) - IMMINENT_S
    if due_t_s <= now:
        return escalate_safe(em, case, op_ids, now, why)
    again_t_s = min(due_t_s, now + RETRY_S)
    case.attempt_t_s = again_t_s - em.config.retry_after_s  # see EmergencyManager._persisting
    text = f"{why}; entry in {event - now:.1f} s: decided again in {again_t_s - now:.1f} s"
    audit = em.audit(now, "deferred", t.id, {"reason": text})
    return Decision(warnings=(text,), audit=(audit,))
