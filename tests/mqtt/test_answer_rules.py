"""The answer rules a pilot's MQTT answer meets in production: the gateway hands it to the
USM's recommendation lifecycle (gcs_utm.services.recommendations) and tells the pilot the
outcome with the recommendation's state after it. The same rules hold for the tests' fake USM
(fake_usm.AnswerBook), which the bridge and session tests use instead of a USM."""

from __future__ import annotations

from dataclasses import replace

from adapters.mqtt.answers import AnswerOutcome, AnswerStatus
from adapters.mqtt.config import MqttConfig
from gcs_utm.clock import ManualClock
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    Alternative,
    FlightPlan,
    Maneuver,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    SysId,
    ThreatId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm

OP = OperationId("op")
RID = RecommendationId("r")
DEADLINE_S = 100.0


def _plan() -> FlightPlan:
    return FlightPlan(
        operation_id=OP,
        version=1,
        waypoints=(
            Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0, t_s=0.0),
            Waypoint4D(lat_deg=40.001, lon_deg=-3.0, alt_amsl_m=700.0, t_s=200.0),
        ),
    )


def _rec(version: int) -> Recommendation:
    hold = Alternative(operation_id=OP, maneuver=Maneuver.HOLD, plan=None, cost=0, risk=0)
    return Recommendation(
        id=RID,
        version=version,
        threat_id=ThreatId("t"),
        threat_kind=ThreatKind.INTRUDER,
        operation_id=OP,
        created_t_s=0.0,
        deadline_t_s=DEADLINE_S,
        alternatives=(hold,),
    )


def _gateway(now_s: float) -> tuple[MqttGateway, ManualClock]:
    """A USM flying ``op`` for operator alice, behind the MQTT gateway (not connected)."""
    clock = ManualClock(now_s)
    airspace = Airspace()
    operation = Operation(
        id=OP,
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=_plan(),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=5.0,
        operational_volume_m=15.0,
        operator="alice",
    )
    airspace.load([operation], [])
    return MqttGateway(Usm(airspace, clock), MqttConfig()), clock


def _ans(
    version: int,
    decision: PilotDecision,
    op: str = "alice",
    t_s: float = 1.0,
    idx: int | None = None,
) -> PilotAnswer:
    return PilotAnswer(
        recommendation_id=RID,
        version=version,
        decision=decision,
        t_s=t_s,
        operator=op,
        alternative_index=idx,
        source="mqtt",
    )


async def test_an_answer_acts_on_the_exact_id_and_version_of_its_operator() -> None:
    gw, _ = _gateway(1.0)

    async def answer(a: PilotAnswer) -> AnswerOutcome:
        return await gw.on_pilot_answer(a)

    await gw.usm.on_recommendation(_rec(2))
    await gw.usm.on_recommendation(_rec(3))  # version 3 supersedes 2
    old = await answer(_ans(2, PilotDecision.REJECT))
    assert old.status is AnswerStatus.REFUSED and "not the current version 3" in old.reason
    future = await answer(_ans(4, PilotDecision.ACCEPT))
    assert future.status is AnswerStatus.REFUSED and "not the current version 3" in future.reason
    other = await answer(_ans(3, PilotDecision.ACCEPT, op="bob"))
    assert other.status is AnswerStatus.REFUSED and "'bob' does not fly" in other.reason
    bad_idx = await answer(_ans(3, PilotDecision.ACCEPT, idx=5))
    assert bad_idx.status is AnswerStatus.REFUSED and "does not exist" in bad_idx.reason
    assert bad_idx.state is RecommendationState.PROPOSED  # a refusal changes nothing
    ok = await answer(_ans(3, PilotDecision.REJECT))
    assert ok.status is AnswerStatus.ACCEPTED and ok.state is RecommendationState.REJECTED
    again = await answer(_ans(3, PilotDecision.REJECT, t_s=2.0))
    assert again.status is AnswerStatus.DUPLICATE
    flip = await answer(_ans(3, PilotDecision.ACCEPT, t_s=2.0))
    assert flip.status is AnswerStatus.REFUSED and "rejected" in flip.reason
    assert gw.usm.recommendations[RID].rec.state is RecommendationState.REJECTED
    unknown = await answer(replace(_ans(3, PilotDecision.ACCEPT), recommendation_id="x"))
    assert unknown.status is AnswerStatus.REFUSED and unknown.state is None


async def test_the_deadline_is_inclusive_and_counts_the_later_of_sent_and_received() -> None:
    gw, _ = _gateway(DEADLINE_S)  # received exactly at the deadline
    await gw.usm.on_recommendation(_rec(3))
    on_time = await gw.on_pilot_answer(_ans(3, PilotDecision.ACCEPT, t_s=0.0))
    assert on_time.status is AnswerStatus.ACCEPTED
    assert on_time.state is RecommendationState.ACCEPTED
    await gw.usm.drain()  # the accepted HOLD is advisory: applied without a vehicle
    # a pilot clock running behind cannot extend the deadline
    gw2, _ = _gateway(DEADLINE_S + 0.5)
    await gw2.usm.on_recommendation(_rec(3))
    late = await gw2.on_pilot_answer(_ans(3, PilotDecision.ACCEPT, t_s=50.0))
    assert late.status is AnswerStatus.REFUSED and "deadline passed" in late.reason
    assert gw2.usm.recommendations[RID].rec.state is RecommendationState.PROPOSED
