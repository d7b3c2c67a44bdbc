"""A restarted life takes over the case of the same condition an earlier life left open
(gcs_utm.core.emergency.adoption, through EmergencyService as ``serve`` runs it): what the
pilot accepted stands and nothing is proposed again, also when the earlier life was killed
while it sent the command (the store then holds UPLOADING, and whether the vehicle got it is
unknown). Proposing it again flew one safety command per life (CI: "hold for sys2 taken in
lives [1, 2]", tests/e2e/test_restart_history.py)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.clock import ManualClock
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import (
    AirspaceSnapshot,
    Recommendation,
    RecommendationState,
    ThreatId,
)
from gcs_utm.services.emergency import EmergencyService

MON = MonitoringConfig()


def _service() -> tuple[EmergencyService, list[Decision]]:
    snap, _threat = sc.scenario_los_2uas()
    em = EmergencyManager(
        sc.FRAME,
        EmergencyConfig(),
        TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON),
        MON,
    )
    decisions: list[Decision] = []

    def snapshot(t_s: float) -> AirspaceSnapshot:
        return replace(snap, t_s=t_s)

    async def on_decision(d: Decision) -> None:
        decisions.append(d)

    return EmergencyService(em, snapshot, ManualClock(snap.t_s), on_decision), decisions


async def _first_life_taken(state: RecommendationState) -> Recommendation:
    """The first life's recommendation for the conflict, accepted and then in ``state``."""
    svc, _ = _service()
    _snap, threat = sc.scenario_los_2uas()
    d = svc.em.on_threat(threat, replace(_snap, t_s=_snap.t_s))
    rec = next(r for r in d.recommendations if r.state is RecommendationState.PROPOSED)
    t = rec.created_t_s + 1.0
    rec = rec.transition(RecommendationState.ACCEPTED, t, "pilot")
    if state is not RecommendationState.ACCEPTED:
        rec = rec.transition(state, t + 0.1, "sending")
    return rec


@pytest.mark.parametrize(
    "state",
    [RecommendationState.ACCEPTED, RecommendationState.UPLOADING, RecommendationState.APPLIED],
)
async def test_a_taken_recommendation_is_adopted_not_proposed_again(
    state: RecommendationState,
) -> None:
    stored = await _first_life_taken(state)
    svc, decisions = _service()
    snap, old = sc.scenario_los_2uas()
    new = replace(old, id=ThreatId("E2-T1-LOS"), detected_at_s=snap.t_s + 5.0)
    svc.adoptions[new.id] = (old, (stored,), ())
    await svc._process(new)  # as the queue hands it over
    proposed = [r for d in decisions for r in d.recommendations]
    assert proposed == []
    assert any(a.action == "adopted" for d in decisions for a in d.audit)
    held = svc.em.recommendation(stored.id)
    # EM knows the version as accepted or applied: its supervision goes on from there
    expected = RecommendationState.APPLIED if state is RecommendationState.APPLIED else None
    assert held is not None and held.version == stored.version
    assert held.state is (expected or RecommendationState.ACCEPTED)
