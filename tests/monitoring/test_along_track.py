"""Conformance tolerant of a fixed wing's own cruise (issue 31.4): a plane filed at 14 m/s
flying its 22 m/s cruise (inside its envelope, 10-30 m/s as ArduPlane's AIRSPEED_MIN/MAX)
is re-timed along its track, not non-conformant (which sent it a back_to_plan every 2 s);
off the track laterally or vertically, or faster than its envelope, it still is."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, operation
from test_monitor import _snapshot

from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.monitoring.along_track import plan_speed_mps
from gcs_utm.model import Operation, PerformanceEnvelope, ThreatKind, VehicleKind

PLANE_ENVELOPE = PerformanceEnvelope(
    climb_rate_mps=5.0,
    descent_rate_mps=3.0,
    min_speed_mps=10.0,
    max_speed_mps=30.0,
    turn_radius_m=80.0,
    can_hover=False,
)


def _plane(kind: VehicleKind = VehicleKind.FIXED_WING) -> Operation:
    """2800 m east at 14 m/s (200 s) at 100 m, filed with a 10 m / 30 m volume."""
    op = operation("P", [(0, 0, 100, 0), (2800, 0, 100, 200)], fg=10, ov=30)
    return dataclasses.replace(op, vehicle_kind=kind, envelope=PLANE_ENVELOPE)


def _kinds(
    op: Operation, t: float, east: float, north: float = 0.0, up: float = 0.0
) -> list[ThreatKind]:
    mon = Monitor(FRAME, MonitoringConfig())
    snap = _snapshot(t, {"P": ((east, north, 100.0 + up), (22.0, 0.0, 0.0))}, [op])
    conformance = (ThreatKind.UAS_IN_CV, ThreatKind.UAS_OUT_OV)
    return [x.kind for x in mon.cycle(snap) if x.kind in conformance]


def test_plan_speed() -> None:
    assert plan_speed_mps(_plane().plan) == pytest.approx(14.0, rel=0.01)


@pytest.mark.parametrize("t", [30.0, 60.0, 100.0, 120.0])
def test_a_plane_at_its_cruise_on_the_track_is_conformant(t: float) -> None:
    assert _kinds(_plane(), t, 22.0 * t) == []


def test_a_multirotor_keeps_its_schedule() -> None:
    """The same progress for a vehicle that can hover: it is out of its plan's time."""
    quad = dataclasses.replace(_plane(VehicleKind.MULTIROTOR), envelope=None)
    assert _kinds(quad, 100.0, 2200.0) == [ThreatKind.UAS_OUT_OV]


def test_a_plane_off_the_track_or_outside_its_envelope_is_not() -> None:
    plane = _plane()
    assert _kinds(plane, 100.0, 2200.0, north=40.0) == [ThreatKind.UAS_OUT_OV]
    assert _kinds(plane, 100.0, 2200.0, up=15.0) == [ThreatKind.UAS_IN_CV]
    # 43 m/s for 60 s: past what 30 m/s (and the 30 s tolerance) allow
    assert _kinds(plane, 60.0, 2600.0) == [ThreatKind.UAS_OUT_OV]
    # 5 m/s: slower than its minimum airspeed allows
    assert _kinds(plane, 150.0, 750.0) == [ThreatKind.UAS_OUT_OV]
