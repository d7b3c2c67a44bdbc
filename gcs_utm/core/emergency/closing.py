"""A closed threat takes the geofences its case created with it.

EM's case of a threat may have created dynamic geofences (a link loss's temporary fence, a
jammed UAS's cylinder, an alert's area; see :mod:`.geofences`). They exist because of the
threat: once it is closed (Monitoring's condition clear, or the hazard's cause gone, see
``gcs_utm.services.threat_lifecycle``) they only keep re-planning healthy neighbours (a link
loss that had ended gave a neighbour three escape plans in one run). Pure, like the manager.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gcs_utm.core.emergency.decision import Decision
from gcs_utm.model import Threat, ThreatStatus

if TYPE_CHECKING:
    from gcs_utm.core.emergency.manager import EmergencyManager


def close_threat(em: EmergencyManager, threat: Threat) -> Decision:
    """EM's decision on a CLOSED ``threat`` (pending proposals superseded, audited) plus the
    removal of the geofences its case created, audited with the threat's message."""
    assert threat.status is ThreatStatus.CLOSED
    case = em.case(threat.id)
    fences = () if case is None else tuple(g.id for g in case.geofences)
    d = em.on_threat_closed(threat)
    if not fences:
        return d
    t_s = threat.updated_at_s if threat.updated_at_s is not None else threat.detected_at_s
    detail: dict[str, object] = {"geofences": list(fences), "reason": threat.message}
    audit = em.audit(t_s, "geofences_removed", threat.id, detail)
    return d.merge(Decision(removed_geofences=fences, audit=(audit,)))
