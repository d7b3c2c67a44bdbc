"""Recommendation lifecycle: an accept carries out exactly the chosen option; every answer is
recorded with who, channel and choice; every version ends in a stored final state."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from gcs_utm.clock import ManualClock
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    Alternative,
    AuditEntry,
    FlightPlan,
    Maneuver,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
    Waypoint4D,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.recommendations import alternative_index_of_row, with_choice
from gcs_utm.services.usm import AnswerStatus, Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import OP, FakeVehicles, make_operation

RID = RecommendationId("t1/UAS1")


def _plan(alt_amsl_m: float) -> FlightPlan:
    return FlightPlan(
        operation_id=OP,
        version=1,
        waypoints=(
            Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=alt_amsl_m, t_s=120.0),
            Waypoint4D(lat_deg=40.001, lon_deg=-3.0, alt_amsl_m=alt_amsl_m, t_s=150.0),
        ),
    )


def _alt(m: Maneuver, alt_amsl_m: float) -> Alternative:
    return Alternative(operation_id=OP, maneuver=m, plan=_plan(alt_amsl_m), cost=0.2, risk=0.1)


def _rec(
    version: int = 1, state: RecommendationState = RecommendationState.PROPOSED
) -> Recommendation:
    return Recommendation(
        id=RID,
        version=version,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=110.0,
        deadline_t_s=130.0,
        selected=_alt(Maneuver.GO_LEFT, 700.0),
        alternatives=(_alt(Maneuver.GO_UP, 720.0), _alt(Maneuver.GO_DOWN, 680.0)),
        state=state,
    )


def _usm() -> tuple[Usm, ManualClock, list[object], FakeVehicles]:
    clock = ManualClock(110.0)
    airspace = Airspace()
    airspace.load([make_operation(100.0)], [])
    recorded: list[object] = []
    usm = Usm(airspace, clock, record=recorded.append)
    vehicles = FakeVehicles()
    usm.attach_vehicles(vehicles)
    return usm, clock, recorded, vehicles


def _answer(
    decision: PilotDecision, index: int | None = None, version: int = 1, source: str = "dashboard"
) -> PilotAnswer:
    return PilotAnswer(
        recommendation_id=RID,
        version=version,
        decision=decision,
        t_s=111.0,
        operator="alice",
        source=source,
        alternative_index=index,
    )


async def test_accepting_an_alternative_uploads_that_alternative_and_names_it() -> None:
    usm, _clock, recorded, vehicles = _usm()
    await usm.on_recommendation(_rec())
    # the prompt's row 1 is alternatives[0] (go_up); row 0 is the proposed go_left
    index = alternative_index_of_row(_rec(), 1)
    assert index == 0
    outcome = await usm.answer(_answer(PilotDecision.ACCEPT, index))
    await usm.drain()
    assert outcome.status is AnswerStatus.ACCEPTED
    assert [w.alt_amsl_m for w in vehicles.uploads[0].waypoints] == [720.0, 720.0]
    assert usm.airspace.operation(OP).plan.reason.endswith("go_up")
    record = usm.recommendations[RID]
    assert record.rec.state is RecommendationState.APPLIED
    assert record.rec.selected is not None and record.rec.selected.maneuver is Maneuver.GO_UP
    # the proposed option is kept among the alternatives, in the chosen one's place
    assert [a.maneuver for a in record.rec.alternatives] == [Maneuver.GO_LEFT, Maneuver.GO_DOWN]
    who = (record.chosen, record.answered_by, record.answered_via)
    assert who == ("go_up", "alice", "dashboard")
    # the store gets the answer itself and every state with the chosen manoeuvre
    answers = [o for o in recorded if isinstance(o, PilotAnswer)]
    assert [(a.version, a.alternative_index, a.operator, a.source) for a in answers] == [
        (1, 0, "alice", "dashboard")
    ]
    audit = [o for o in recorded if isinstance(o, AuditEntry) and o.action == "answer_accept"]
    assert audit[0].detail["maneuver"] == "go_up" and audit[0].detail["outcome"] == "accepted"
    stored = [o for o in recorded if isinstance(o, Recommendation)]
    accepted = [r for r in stored if r.state is RecommendationState.ACCEPTED]
    assert accepted[0].selected is not None and accepted[0].selected.maneuver is Maneuver.GO_UP
    assert "go_up" in accepted[0].reason and "alice" in accepted[0].reason
    events = [e.text for e in usm.events]
    assert any("v1 accepted go_up (pilot's choice) by alice (dashboard)" in t for t in events)


async def test_accepting_the_proposed_option_and_a_duplicate() -> None:
    usm, _clock, _recorded, vehicles = _usm()
    await usm.on_recommendation(_rec())
    assert (await usm.answer(_answer(PilotDecision.ACCEPT))).status is AnswerStatus.ACCEPTED
    again = await usm.answer(_answer(PilotDecision.ACCEPT))
    other = await usm.answer(_answer(PilotDecision.ACCEPT, 1))
    await usm.drain()
    assert again.status is AnswerStatus.DUPLICATE
    assert other.status is AnswerStatus.REFUSED
    assert [w.alt_amsl_m for w in vehicles.uploads[0].waypoints] == [700.0, 700.0]


async def test_an_alternative_that_does_not_exist_is_refused() -> None:
    usm, _clock, recorded, vehicles = _usm()
    await usm.on_recommendation(_rec())
    outcome = await usm.answer(_answer(PilotDecision.ACCEPT, 2))
    assert outcome.status is AnswerStatus.REFUSED and "does not exist" in outcome.reason
    assert usm.recommendations[RID].rec.state is RecommendationState.PROPOSED
    assert not vehicles.uploads
    assert [o for o in recorded if isinstance(o, PilotAnswer)]  # refused answers recorded too


async def test_superseded_and_expired_versions_are_stored_in_their_final_state() -> None:
    usm, clock, recorded, _vehicles = _usm()
    await usm.on_recommendation(_rec(1))
    # EM expired v1 and re-planned: its notice (v1 expired) comes with v2
    await usm.on_recommendation(_rec(1, RecommendationState.EXPIRED))
    await usm.on_recommendation(_rec(2))
    # a new version replacing a still-proposed one supersedes it even without EM's notice
    await usm.on_recommendation(_rec(3))
    clock.set(131.0)
    await usm.expire_due()
    final = {
        (r.version, r.state)
        for r in recorded
        if isinstance(r, Recommendation) and r.state is not RecommendationState.PROPOSED
    }
    assert final == {
        (1, RecommendationState.EXPIRED),
        (2, RecommendationState.SUPERSEDED),
        (3, RecommendationState.EXPIRED),
    }
    texts = [e.text for e in usm.events]
    assert f"{RID} v2 superseded by v3" in texts


async def test_an_old_version_or_a_late_answer_is_never_accepted() -> None:
    usm, clock, _recorded, vehicles = _usm()
    await usm.on_recommendation(_rec(1))
    await usm.on_recommendation(_rec(2))
    old = await usm.answer(_answer(PilotDecision.ACCEPT, version=1))
    assert old.status is AnswerStatus.REFUSED
    # an answer stamped before the deadline that arrives after it is refused too
    clock.set(131.0)
    late = await usm.answer(dataclasses.replace(_answer(PilotDecision.ACCEPT, version=2)))
    assert late.status is AnswerStatus.REFUSED and late.reason == "deadline passed"
    assert not vehicles.uploads


def test_with_choice_swaps_the_chosen_option_first() -> None:
    rec = with_choice(_rec(), 1)
    assert rec.selected is not None and rec.selected.maneuver is Maneuver.GO_DOWN
    assert [a.maneuver for a in rec.alternatives] == [Maneuver.GO_UP, Maneuver.GO_LEFT]
    assert with_choice(_rec(), None) == _rec()
