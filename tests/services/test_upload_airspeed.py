"""The plan an accepted recommendation uploads to a fixed wing carries its minimum airspeed
(issue 31.4: serve's plans for the plane carried "set groundspeed 5"): the USM passes the
operation's envelope minimum speed to the upload, which raises every airspeed item to it
(adapters/mavlink/mission.py); a multirotor's has none."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from gcs_utm.clock import ManualClock
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    Alternative,
    Maneuver,
    Recommendation,
    RecommendationId,
    ThreatId,
    ThreatKind,
    VehicleKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import OP, FakeVehicles, make_operation, make_plan


async def _uploaded_min_speed(kind: VehicleKind, cruise_mps: float) -> tuple[float, float]:
    """(the minimum speed the accepted plan was uploaded with, the envelope's)."""
    op = dataclasses.replace(make_operation(100.0), vehicle_kind=kind, cruise_speed_mps=cruise_mps)
    airspace = Airspace()
    airspace.load([op], [])
    clock = ManualClock(110.0)
    usm = Usm(airspace, clock, record=lambda _r: None)
    vehicles = FakeVehicles()
    usm.attach_vehicles(vehicles)
    rec = Recommendation(
        id=RecommendationId("r1"), version=1, threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION, operation_id=OP, created_t_s=110.0,
        deadline_t_s=200.0,
        selected=Alternative(operation_id=OP, maneuver=Maneuver.GO_DOWN,
                             plan=make_plan(1, 120.0), cost=1.0, risk=0.1),
    )  # fmt: skip
    await usm.on_recommendation(rec)
    await usm.answer(
        PilotAnswer(recommendation_id=rec.id, version=1, decision=PilotDecision.ACCEPT, t_s=111.0)
    )
    await usm.drain()
    assert len(vehicles.min_speeds) == 1
    return vehicles.min_speeds[0], op.performance().min_speed_mps


async def test_a_fixed_wing_upload_carries_its_minimum_airspeed() -> None:
    sent, envelope = await _uploaded_min_speed(VehicleKind.FIXED_WING, 22.0)
    assert envelope > 5.0 and sent == envelope
    sent, _ = await _uploaded_min_speed(VehicleKind.MULTIROTOR, 5.0)
    assert sent == 0.0
