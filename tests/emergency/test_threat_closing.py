"""A closed threat takes the geofences EM created for it along (issue 31: a link loss that
had ended kept re-planning a healthy neighbour around its temporary fence)."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.model import RecommendationState, ThreatKind, ThreatStatus
from tests.emergency.test_em import make_em


def test_closing_a_link_loss_removes_its_fence_and_supersedes_the_reroute() -> None:
    lost = sc.make_operation("A", [(0, 0, 100), (1000, 0, 100)])
    # B crosses A's predicted position (100 m east, 10 s ahead) from south to north
    neighbour = sc.make_operation("B", [(100, -500, 100), (100, 500, 100)])
    snap = sc.snapshot([lost, neighbour])
    threat = sc.threat(ThreatKind.COMMUNICATION_FAILURE, ["A"])
    em = make_em()
    d = em.on_threat(threat, snap)
    (fence,) = d.geofences
    reroutes = [r for r in d.recommendations if r.operation_id == "B"]
    assert reroutes and reroutes[0].state is RecommendationState.PROPOSED
    closed = replace(
        threat,
        status=ThreatStatus.CLOSED,
        updated_at_s=snap.t_s + 20.0,
        message="closed: positions of A flow again",
    )
    out = em.close_threat(closed)
    assert out.removed_geofences == (fence.id,)
    assert reroutes[0].id in out.superseded
    removed = [a for a in out.audit if a.action == "geofences_removed"]
    assert len(removed) == 1 and removed[0].detail["reason"] == closed.message
    assert em.open_threats() == []
    # a threat EM made no fence for removes none
    other = sc.threat(ThreatKind.UAS_IN_CV, ["A"])
    em.on_threat(other, snap)
    out = em.close_threat(replace(other, status=ThreatStatus.CLOSED))
    assert out.removed_geofences == ()
