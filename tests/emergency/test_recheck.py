"""An accepted plan is checked again against the airspace as it is right before its upload
(issue 30, class 2): a UAS that appeared after the decision, on the plan's new path, makes
the USM fail the recommendation instead of uploading it, and EM decides again."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    AirspaceSnapshot,
    RecommendationState,
    ThreatKind,
    TrackId,
)
from gcs_utm.services.usm import AnswerStatus

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))
from test_immediate import _crossing, _track, make_em, sc
from test_usm import _rec, _usm
from usm_fakes import FakeVehicles


def _with_c(snap: AirspaceSnapshot) -> AirspaceSnapshot:
    """C appears flying east at 130 m, over the crossing 40 s from now."""
    c = sc.make_operation("C", [(-400, 0, 130), (1000, 0, 130)], priority=3, t0_s=snap.t_s)
    track = replace(_track("C", -400.0, 0.0, 10.0, 0.0, snap.t_s), alt_amsl_m=130.0)
    return replace(
        snap,
        operations={**snap.operations, c.id: c},
        tracks={**snap.tracks, TrackId("C"): track},
    )


def test_a_plan_into_a_uas_that_appeared_since_the_decision_is_not_uploaded() -> None:
    """B's plan climbs over the crossing (go_up, 128 m, 37-43 s ahead). At the decision it
    is clear; when C has appeared at 130 m on that stretch by the time the pilot accepts, the
    re-check names the loss, and EM's decision after the failure is a new one on the
    airspace with C in it."""
    snap = _crossing(400.0)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=35.0)
    em = make_em()
    (rec,) = em.on_threat(threat, snap).recommendations
    assert rec.selected is not None and rec.selected.plan is not None
    assert em.plan_problem(rec, snap) == ""
    later = replace(_with_c(snap), t_s=snap.t_s + 2.0)
    problem = em.plan_problem(rec, later)
    assert problem.startswith("t1/B v1 re-checked before its upload: separation with C")
    assert em.on_answer(rec, True, later).recommendations[0].state is RecommendationState.ACCEPTED
    d = em.on_outcome(rec.id, rec.version, False, f"not uploaded: {problem}", later)
    states = {(r.version, r.state) for r in d.recommendations}
    assert (1, RecommendationState.FAILED) in states
    new = [r for r in d.recommendations if r.version > 1]
    assert new and all(em.plan_problem(r, later) == "" for r in new), d


async def test_the_usm_fails_a_plan_its_check_refuses_and_uploads_nothing() -> None:
    vehicles = FakeVehicles()
    usm, _clock, _ = _usm(vehicles)
    asked = []
    usm.lifecycle.plan_check = lambda rec: (
        asked.append(rec.id) or "separation with C at t=130.0 (2.0 m)"
    )
    await usm.on_recommendation(_rec())
    answer = PilotAnswer(
        recommendation_id=_rec().id, version=1, decision=PilotDecision.ACCEPT, t_s=111.0
    )
    assert (await usm.answer(answer)).status is AnswerStatus.ACCEPTED
    await usm.drain()
    record = usm.recommendations[_rec().id]
    assert asked == [_rec().id]
    assert record.rec.state is RecommendationState.FAILED
    assert record.error == "not uploaded: separation with C at t=130.0 (2.0 m)"
    assert vehicles.uploads == []
