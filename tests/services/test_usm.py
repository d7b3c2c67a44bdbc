"""USM: answers matched to id+version, upload only marked applied after readback, hazards
coalesced, nothing dropped."""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from gcs_utm.clock import ManualClock
from gcs_utm.messages import HazardReport, PilotAnswer, PilotDecision
from gcs_utm.model import (
    Alternative,
    Autopilot,
    Command,
    CommandKind,
    FlightPlan,
    Maneuver,
    Operation,
    OperationId,
    OperationState,
    Recommendation,
    RecommendationId,
    RecommendationState,
    SysId,
    Threat,
    ThreatId,
    ThreatKind,
    VehicleKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import AnswerStatus, Usm, resume_index

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import OP, FakeVehicles, make_operation, make_plan


def _plan(version: int, t0: float = 100.0) -> FlightPlan:
    return make_plan(version, t0)


def _op() -> Operation:
    return make_operation(100.0)


def _rec(version: int = 1, deadline: float = 200.0) -> Recommendation:
    return Recommendation(
        id=RecommendationId("r1"),
        version=version,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=110.0,
        deadline_t_s=deadline,
        selected=Alternative(
            operation_id=OP, maneuver=Maneuver.GO_DOWN, plan=_plan(1, 120.0), cost=1.0, risk=0.1
        ),
    )


def _usm(vehicles: FakeVehicles) -> tuple[Usm, ManualClock, list[object]]:
    clock = ManualClock(110.0)
    airspace = Airspace()
    airspace.load([_op()], [])
    recorded: list[object] = []
    usm = Usm(airspace, clock, record=recorded.append)
    usm.attach_vehicles(vehicles)
    return usm, clock, recorded


def _answer(decision: PilotDecision, version: int = 1, t_s: float = 111.0) -> PilotAnswer:
    return PilotAnswer(
        recommendation_id=RecommendationId("r1"), version=version, decision=decision, t_s=t_s
    )


async def test_accept_uploads_and_installs_new_plan_version_after_readback() -> None:
    vehicles = FakeVehicles()
    usm, _clock, recorded = _usm(vehicles)
    await usm.on_recommendation(_rec())
    out = await usm.answer(_answer(PilotDecision.ACCEPT))
    assert out.status is AnswerStatus.ACCEPTED
    await usm.drain()
    record = usm.recommendations[RecommendationId("r1")]
    assert record.rec.state is RecommendationState.APPLIED
    assert record.verified
    assert len(vehicles.uploads) == 1
    assert usm.airspace.operation(OP).plan.version == 2
    assert any(
        isinstance(r, Recommendation) and r.state is RecommendationState.APPLIED for r in recorded
    )


async def test_unverified_upload_is_failed_never_applied() -> None:
    vehicles = FakeVehicles(verified=False)
    usm, _clock, _ = _usm(vehicles)
    await usm.on_recommendation(_rec())
    await usm.answer(_answer(PilotDecision.ACCEPT))
    await usm.drain()
    record = usm.recommendations[RecommendationId("r1")]
    assert record.rec.state is RecommendationState.FAILED
    assert "mismatch" in record.error
    assert usm.airspace.operation(OP).plan.version == 1
    assert len(vehicles.uploads) == usm.config.upload_attempts


async def test_answer_matching_version_duplicate_and_expiry() -> None:
    usm, _clock, _ = _usm(FakeVehicles())
    rejected: list[tuple[str, bool]] = []

    async def em_sink(rec: Recommendation, accepted: bool) -> None:
        rejected.append((rec.id, accepted))

    usm.attach_answer_sink(em_sink)
    await usm.on_recommendation(_rec())
    wrong = await usm.answer(_answer(PilotDecision.ACCEPT, version=2))
    assert wrong.status is AnswerStatus.REFUSED and "version" in wrong.reason
    first = await usm.answer(_answer(PilotDecision.REJECT))
    assert first.status is AnswerStatus.ACCEPTED
    dup = await usm.answer(_answer(PilotDecision.REJECT))
    assert dup.status is AnswerStatus.DUPLICATE
    flip = await usm.answer(_answer(PilotDecision.ACCEPT))
    assert flip.status is AnswerStatus.REFUSED
    assert rejected == [("r1", False)]
    unknown = await usm.answer(
        dataclasses.replace(
            _answer(PilotDecision.ACCEPT), recommendation_id=RecommendationId("nope")
        )
    )
    assert unknown.status is AnswerStatus.REFUSED


async def test_late_answer_refused() -> None:
    usm, _clock, _ = _usm(FakeVehicles())
    await usm.on_recommendation(_rec(deadline=150.0))
    out = await usm.answer(_answer(PilotDecision.ACCEPT, t_s=151.0))
    assert out.status is AnswerStatus.REFUSED
    assert "deadline" in out.reason


async def test_command_recommendation_suspends_operation() -> None:
    vehicles = FakeVehicles()
    usm, _clock, _ = _usm(vehicles)
    rec = dataclasses.replace(
        _rec(), selected=None, command=Command(kind=CommandKind.HOLD, operation_id=OP)
    )
    await usm.on_recommendation(rec)
    await usm.answer(_answer(PilotDecision.ACCEPT))
    await usm.drain()
    assert vehicles.commands[0].kind is CommandKind.HOLD
    assert usm.airspace.operation(OP).state is OperationState.SUSPENDED
    assert usm.recommendations[RecommendationId("r1")].rec.state is RecommendationState.APPLIED


@pytest.mark.parametrize("gap_s, expected", [(5.0, 1), (60.0, 2)])
async def test_hazards_coalesce_within_cooldown(gap_s: float, expected: int) -> None:
    usm, _clock, _ = _usm(FakeVehicles())
    seen: list[Threat] = []

    async def sink(threats: list[Threat]) -> None:
        seen.extend(threats)

    usm.attach_threat_sink(sink)
    for t in (100.0, 100.0 + gap_s):
        usm.on_hazard(HazardReport(kind=ThreatKind.JAMMING_ATTACK, t_s=t, sys_id=SysId(1)))
    await usm.drain()
    assert len(seen) == expected
    assert seen[0].uas_ids == (OP,)


@dataclass
class _Item:
    command: int
    x: int = 0
    y: int = 0
    z: float = 0.0
    frame: int = 0
    param2: float = 0.0


@dataclass
class _Key:
    sys_id: int


@dataclass
class _Info:
    key: _Key
    autopilot: Autopilot = Autopilot.PX4
    vehicle_kind: VehicleKind = VehicleKind.MULTIROTOR


async def test_vehicle_without_operation_gets_one_from_its_mission() -> None:
    class Port(FakeVehicles):
        async def download_mission(self, sys_id: SysId) -> list[_Item]:
            return [
                _Item(command=16, x=400000000, y=-30000000, z=700.0),
                _Item(command=16, x=400010000, y=-30000000, z=700.0),
            ]

    usm, _clock, _ = _usm(Port())
    usm.on_vehicle(_Info(key=_Key(sys_id=1)))  # sysid 1 already flies UAS1: nothing new
    usm.on_vehicle(_Info(key=_Key(sys_id=9)))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(9))
    assert op is not None and op.id == "sys9"
    assert len(op.plan.waypoints) == 2
    assert op.plan.waypoints[1].t_s > op.plan.waypoints[0].t_s
    assert len(usm.airspace.operations) == 2


def test_resume_index_is_the_first_waypoint_still_ahead() -> None:
    plan = dataclasses.replace(
        make_plan(2, 100.0),
        waypoints=(*make_plan(2, 100.0).waypoints, make_plan(2, 140.0).waypoints[1]),
    )  # t = 100, 130, 170
    assert resume_index(plan, 99.0) == 0
    assert resume_index(plan, 100.0) == 1  # the vehicle is at (or past) the first point
    assert resume_index(plan, 129.9) == 1
    assert resume_index(plan, 150.0) == 2
    assert resume_index(plan, 500.0) == 2  # all in the past: the last point


async def test_upload_starts_at_the_first_waypoint_ahead_when_accepted_late() -> None:
    """A new plan starts where the UAS was when TD computed it; accepted 2 s later, the vehicle
    has moved on (a 28 m/s fixed wing by 55 m): flying to that point would turn it back."""
    vehicles = FakeVehicles()
    usm, clock, _recorded = _usm(vehicles)
    rec = _rec()
    assert rec.selected is not None and rec.selected.plan is not None
    now_plan = make_plan(1, 110.0)  # first waypoint: the UAS at t = 110 (recommendation time)
    rec = dataclasses.replace(rec, selected=dataclasses.replace(rec.selected, plan=now_plan))
    await usm.on_recommendation(rec)
    clock.advance(2.0)
    out = await usm.answer(_answer(PilotDecision.ACCEPT, t_s=112.0))
    assert out.status is AnswerStatus.ACCEPTED
    await usm.drain()
    assert vehicles.start_indices == [1]
    # a plan starting in the future is flown from its first waypoint
    vehicles2 = FakeVehicles()
    usm2, _c, _r = _usm(vehicles2)
    await usm2.on_recommendation(_rec())  # plan from t = 120, accepted at 111
    await usm2.answer(_answer(PilotDecision.ACCEPT))
    await usm2.drain()
    assert vehicles2.start_indices == [0]


async def test_upload_gives_the_vehicle_its_envelope_climb_and_descent_rates() -> None:
    """A climb or descent on the spot is flown at the vehicle's own rates: the mission's
    waits are computed with the envelope's descent rate (1.5 m/s for a multirotor), not the
    climb rate (3 m/s)."""
    vehicles = FakeVehicles()
    usm, _clock, _ = _usm(vehicles)
    await usm.on_recommendation(_rec())
    await usm.answer(_answer(PilotDecision.ACCEPT))
    await usm.drain()
    assert vehicles.rates == [(3.0, 1.5)]


def test_measurements_counted_per_vehicle_and_unclaimed_system_ids_counted() -> None:
    from gcs_utm.model import Measurement, MeasurementSource

    airspace = Airspace()
    usm = Usm(airspace, ManualClock(100.0))
    got: list[Measurement] = []
    usm.attach_measurement_sink(got.append)

    def m(sys_id: int, vehicle: str) -> Measurement:
        return Measurement(
            source=MeasurementSource.TELEMETRY,
            capture_t_s=100.0,
            receipt_t_s=100.01,
            lat_deg=47.0,
            lon_deg=8.0,
            alt_amsl_m=500.0,
            sys_id=SysId(sys_id),
            vehicle=vehicle,
        )

    usm.on_measurement(m(1, "10.0.0.1:14550"))
    usm.on_measurement(m(1, "10.0.0.2:14550"))
    assert set(usm.telemetry) == {"telemetry:1@10.0.0.1:14550", "telemetry:1@10.0.0.2:14550"}
    assert usm.counters["unknown_vehicle_measurements"] == 2
    # once an operation flies system id 1, its measurements are no longer unknown; they are
    # handed on unchanged (Tracking associates the system id with the operation)
    airspace.add_operation(_op())
    usm.on_measurement(m(1, "10.0.0.1:14550"))
    assert usm.counters["unknown_vehicle_measurements"] == 2
    assert len(got) == 3 and got[-1].sys_id == 1
    # a vehicle that flies again: the most recently filed operation is the one it flies
    op = _op()
    again = dataclasses.replace(
        op,
        id=OperationId("again"),
        plan=dataclasses.replace(op.plan, operation_id=OperationId("again")),
    )
    airspace.add_operation(again)
    assert airspace.by_sys_id(SysId(1)) == again


def test_link_health_kept_per_vehicle_sharing_a_system_id() -> None:
    """Two vehicles flying system id 4 from two addresses each keep their link health; the
    dashboard's one-per-system-id view shows the one heard last."""
    from gcs_utm.messages import LinkHealth

    usm = Usm(Airspace(), ManualClock(100.0))

    def h(vehicle: str, last_heard: float, lost: int) -> LinkHealth:
        return LinkHealth(
            sys_id=SysId(4),
            link="udpin:0.0.0.0:14550",
            last_heard_t_s=last_heard,
            rate_hz=10.0,
            received=100,
            lost=lost,
            bad_frames=0,
            reboots=0,
            vehicle=vehicle,
        )

    usm.on_link_health(h("10.0.0.1:14550", 100.0, 0))
    usm.on_link_health(h("10.0.0.2:14550", 101.0, 30))
    usm.on_link_health(h("10.0.0.1:14550", 100.5, 2))  # an update, not a third vehicle
    assert {k: v.lost for k, v in usm.health.items()} == {
        (SysId(4), "10.0.0.1:14550"): 2,
        (SysId(4), "10.0.0.2:14550"): 30,
    }
    assert usm.health_by_sys_id()[SysId(4)].vehicle == "10.0.0.2:14550"


def test_vehicle_status_kept_per_vehicle_sharing_a_system_id() -> None:
    """As link health: two vehicles flying system id 4 each keep their status (mode, battery);
    the one-per-system-id view shows the latest report."""
    from gcs_utm.messages import VehicleStatus

    usm = Usm(Airspace(), ManualClock(100.0))
    usm.on_status(VehicleStatus(sys_id=SysId(4), t_s=100.0, battery_pct=80.0, vehicle="a:1"))
    usm.on_status(VehicleStatus(sys_id=SysId(4), t_s=101.0, battery_pct=20.0, vehicle="b:1"))
    usm.on_status(VehicleStatus(sys_id=SysId(4), t_s=100.5, battery_pct=79.0, vehicle="a:1"))
    assert {k: v.battery_pct for k, v in usm.statuses.items()} == {
        (SysId(4), "a:1"): 79.0,
        (SysId(4), "b:1"): 20.0,
    }
    assert usm.statuses_by_sys_id()[SysId(4)].vehicle == "b:1"
