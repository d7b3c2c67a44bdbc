"""A restarted service takes over the case of a threat its previous life left open.

After a kill -9 the new life detects the same condition again (a GNSS still degraded, a
conflict still predicted) under a new threat id. Deciding afresh proposed, and with
auto-accept applied, the same safety command once per life (4 lands and a hold after 10
restarts). Adopting the previous life's case instead keeps what it put in force (accepted,
uploading or applied recommendations, the dynamic geofences it created) as the new threat's
case: nothing is proposed again, supervision goes on from there (see :mod:`.supervision`),
and closing the threat later removes the adopted geofences. With nothing in force (the pilot
had not answered yet: that prompt died with the process) there is nothing to adopt and EM
decides as for any new threat. Pure, like the manager.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import SINGLE_MANEUVERS, Case, Decision, Mode
from gcs_utm.model import Geofence, Recommendation, RecommendationState, Threat

IN_FORCE = (
    RecommendationState.ACCEPTED,
    RecommendationState.UPLOADING,
    RecommendationState.APPLIED,
)
"""Accepted by the pilot. UPLOADING too: a life killed while it sent the command or plan
leaves that state in the store, and whether the vehicle got it is unknown; deciding afresh
proposed the same command a second time."""


def adopt_case(
    em: EmContext,
    threat: Threat,
    *,
    inherited: Threat,
    recommendations: Sequence[Recommendation],
    geofences: Sequence[Geofence],
    now: float,
) -> Decision | None:
    """Make the case of ``inherited`` (a previous life's open threat; its latest
    ``recommendations`` and the ``geofences`` its case created that are still active) the case
    of ``threat``, the same condition detected again. None when nothing of it is in force:
    then the caller decides as usual."""
    in_force = [r for r in recommendations if r.state in IN_FORCE]
    if not in_force and not geofences:
        return None
    action = em.config.action_for(threat.kind)
    case = Case(threat=threat, action=action, attempt_t_s=now, geofences=list(geofences))
    for stored in in_force:
        rec = stored
        if rec.state is RecommendationState.UPLOADING:
            # EM has no UPLOADING (the USM's state): an upload with no outcome is accepted,
            # and supervision checks its effect after the upload time (.supervision)
            rec = replace(rec, state=RecommendationState.ACCEPTED)
        em.record(rec)
        case.rec_ids.add(rec.id)
        if rec.command is not None:
            case.modes[rec.operation_id] = Mode.COMMAND
        elif action is Action.ALTERNATIVE_PLANS:
            case.modes[rec.operation_id] = Mode.MULTI
        else:
            case.modes[rec.operation_id] = Mode.SINGLE
            case.maneuvers[rec.operation_id] = SINGLE_MANEUVERS.get(action, frozenset())
    em.cases[case.threat.id] = case  # a previous life's case, as it is
    detail: dict[str, object] = {
        "reason": f"the condition of {inherited.id} (an earlier life's) detected again",
        "from": inherited.id,
        "in_force": [f"{r.id} v{r.version} {r.state.value}" for r in in_force],
        "geofences": [g.id for g in geofences],
    }
    return Decision(audit=(em.audit(now, "adopted", threat.id, detail),))
