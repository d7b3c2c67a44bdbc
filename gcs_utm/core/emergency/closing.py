"""A closed threat takes the geofences its case created with it.

EM's case of a threat may have created dynamic geofences (a link loss's temporary fence, a
jammed UAS's cylinder, an alert's area; see :mod:`.geofences`). They exist because of the
threat: once it is closed (Monitoring's condition clear, or the hazard's cause gone, see
``gcs_utm.services.threat_lifecycle``) they only keep re-planning healthy neighbours (a link
loss that had ended gave a neighbour three escape plans in one run). Pure, like the manager.
"""

from __future__ import annotations

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Decision
from gcs_utm.model import Recommendation, RecommendationState, Threat, ThreatStatus


def supersede_pending(em: EmContext, threat: Threat) -> Decision:
    """The case of ``threat`` (CLOSED) ends: its pending proposals are superseded (accepted
    ones stand), audited with the threat's message (why it closed)."""
    case = em.cases.pop(threat.id, None)
    if case is None:
        return Decision()
    t = threat.updated_at_s if threat.updated_at_s is not None else threat.detected_at_s
    recs: list[Recommendation] = []
    for rid in sorted(case.rec_ids):
        cur = em.recs[rid]
        if cur.state is RecommendationState.PROPOSED:
            new = cur.transition(RecommendationState.SUPERSEDED, t, "threat closed")
            em.recs[rid] = new
            recs.append(new)
    # why it closed: the closed threat's message ends "; closed: <reason>" (Monitoring's and
    # the USM's closings both word it so)
    detail: dict[str, object] = {"superseded": [r.id for r in recs], "reason": threat.message}
    return Decision(
        recommendations=tuple(recs),
        superseded=tuple(r.id for r in recs),
        audit=(em.audit(t, "threat_closed", threat.id, detail),),
    )


def close_threat(em: EmContext, threat: Threat) -> Decision:
    """EM's decision on a CLOSED ``threat`` (pending proposals superseded, audited) plus the
    removal of the geofences its case created, audited with the threat's message."""
    assert threat.status is ThreatStatus.CLOSED
    case = em.case(threat.id)
    fences = () if case is None else tuple(g.id for g in case.geofences)
    d = supersede_pending(em, threat)
    if not fences:
        return d
    t_s = threat.updated_at_s if threat.updated_at_s is not None else threat.detected_at_s
    detail: dict[str, object] = {"geofences": list(fences), "reason": threat.message}
    audit = em.audit(t_s, "geofences_removed", threat.id, detail)
    return d.merge(Decision(removed_geofences=fences, audit=(audit,)))
