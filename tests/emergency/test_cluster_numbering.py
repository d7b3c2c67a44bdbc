"""EM's version numbers when a cluster member takes over (gcs_utm.cluster.decisions): the
pending version takes the number the member proposed it under, and the next version of an
id is numbered above versions stored elsewhere."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.clock import ManualClock
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import AirspaceSnapshot, OperationId, RecommendationId, RecommendationState
from gcs_utm.services.emergency import EmergencyService

MON = MonitoringConfig()


def _service() -> tuple[EmergencyService, Case, OperationId]:
    snap, threat = sc.scenario_los_2uas()
    em = EmergencyManager(
        sc.FRAME,
        EmergencyConfig(),
        TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON),
        MON,
    )

    def snapshot(t_s: float) -> AirspaceSnapshot:
        return replace(snap, t_s=t_s)

    async def on_decision(d: Decision) -> None:
        return None

    case = Case(threat=threat, action="resolve", attempt_t_s=snap.t_s)
    svc = EmergencyService(em, snapshot, ManualClock(snap.t_s), on_decision)
    return svc, case, threat.uas_ids[0]


def test_the_pending_version_takes_a_higher_adopted_number_only() -> None:
    svc, case, op_id = _service()
    em = svc.em
    (rec,) = em.issue(case, op_id, case.attempt_t_s, reason="first").recommendations
    assert rec.version == 1
    assert not svc.renumber(RecommendationId("other"), 5)  # not EM's
    assert svc.renumber(rec.id, 3)
    assert not svc.renumber(rec.id, 2)  # never lowered
    held = em.recommendation(rec.id)
    assert held is not None and (held.version, held.state) == (3, RecommendationState.PROPOSED)
    nxt = em.issue(case, op_id, case.attempt_t_s, reason="again").recommendations
    assert [(r.version, r.state) for r in nxt] == [
        (3, RecommendationState.SUPERSEDED),
        (4, RecommendationState.PROPOSED),
    ]
    # a version no longer pending keeps its number (its answer came under it)
    em.record(nxt[-1].transition(RecommendationState.ACCEPTED, case.attempt_t_s, "pilot"))
    assert not svc.renumber(rec.id, 9)


def test_the_next_version_is_numbered_above_versions_stored_elsewhere() -> None:
    svc, case, op_id = _service()
    em = svc.em
    (rec,) = em.issue(case, op_id, case.attempt_t_s, reason="first").recommendations
    em.record(rec.transition(RecommendationState.ACCEPTED, case.attempt_t_s, "pilot"))
    svc.continue_after(rec.id, 2)
    svc.continue_after(rec.id, 1)  # a floor is never lowered
    svc.continue_after(RecommendationId("unknown"), 7)  # not EM's: ignored
    (again,) = em.issue(case, op_id, case.attempt_t_s, reason="again").recommendations
    assert again.version == 3
