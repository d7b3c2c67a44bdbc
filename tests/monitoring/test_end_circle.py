"""A fixed wing's circle round its last waypoint, checked against geofences before the plan
ends (gcs_utm.core.monitoring.end_circle): a fence beside the end point was first predicted
once the plan had ended, seconds before the circle entered it (enc_7_0003_endpoint_vertical:
52 m from the end, entered on the 80 m circle 5 s after it)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, cylinder, operation

from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.monitoring.end_circle import EndRings, end_ring
from gcs_utm.core.monitoring.strategic import plan_local, plan_vs_geofences
from gcs_utm.envelope import FIXED_WING_TURN_RADIUS_M
from gcs_utm.model import (
    AirspaceSnapshot,
    Operation,
    OperationId,
    PredictedTrajectories,
    ThreatKind,
    Track,
    TrackId,
    VehicleKind,
)

SPEED_MPS = 20.0
END_T_S = 20.0
# 100 m south of the end point: the 80 m circle comes 20 m from its centre (radius 40),
# the path (eastbound on north = 0) and its straight extrapolation stay 60 m from its edge.
FENCE = cylinder("F", (0.0, -100.0), 40.0)


def _op(kind: VehicleKind) -> Operation:
    """Eastbound at 20 m/s, ending at (0, 0) at t = 20 s."""
    op = operation("A", [(-1000.0, 0.0, 100.0, -30.0), (0.0, 0.0, 100.0, END_T_S)], fg=10, ov=10)
    return dataclasses.replace(op, vehicle_kind=kind, cruise_speed_mps=SPEED_MPS)


def _snapshot(op: Operation) -> AirspaceSnapshot:
    """At t = 0, 400 m before the end, predicted straight on at its speed for 60 s."""
    k = np.arange(61, dtype=float)
    row = np.zeros((61, 4))
    row[:, 0] = -400.0 + SPEED_MPS * k
    row[:, 2] = 100.0
    row[:, 3] = k
    track = Track(
        id=TrackId("A"),
        t_s=0.0,
        lat_deg=0.0,
        lon_deg=0.0,
        alt_amsl_m=100.0,
        east_m=-400.0,
        north_m=0.0,
        vel_enu_mps=(SPEED_MPS, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=op.id,
    )
    pred = PredictedTrajectories(
        t_s=0.0, track_ids=(TrackId("A"),), points=row[None], sigma_m=np.ones((1, 61))
    )
    return AirspaceSnapshot(
        t_s=0.0,
        operations={op.id: op},
        tracks={TrackId("A"): track},
        geofences=(FENCE,),
        prediction=pred,
    )


def test_the_circle_after_the_plan_is_a_geofence_conflict_before_the_end() -> None:
    mon = Monitor(FRAME, MonitoringConfig(conformance_time_tolerance_s=1000.0))
    (t,) = mon.cycle(_snapshot(_op(VehicleKind.FIXED_WING)))
    assert t.kind is ThreatKind.GEOFENCE_CONFLICT and t.geofence_id == "F"
    # after the end, within one turn of the circle
    turn_s = 2 * np.pi * FIXED_WING_TURN_RADIUS_M / SPEED_MPS
    assert (
        END_T_S < t.predicted_event_at_s < END_T_S + turn_s + FIXED_WING_TURN_RADIUS_M / SPEED_MPS
    )


def test_a_multirotor_stops_at_its_end_point_and_is_not_flagged() -> None:
    mon = Monitor(FRAME, MonitoringConfig(conformance_time_tolerance_s=1000.0))
    assert mon.cycle(_snapshot(_op(VehicleKind.MULTIROTOR))) == []


def test_a_plan_whose_circle_enters_a_fence_is_not_clear_of_it() -> None:
    # What TD verifies its plans with: the same circle, so that it does not propose a plan
    # Monitoring flags; the multirotor's plan is clear.
    cfg = MonitoringConfig()
    fw, mr = _op(VehicleKind.FIXED_WING), _op(VehicleKind.MULTIROTOR)
    (c,) = plan_vs_geofences(fw.plan, fw, (FENCE,), FRAME, cfg)
    assert c.geofence_id == "F" and c.entry_t_s > END_T_S
    assert plan_vs_geofences(mr.plan, mr, (FENCE,), FRAME, cfg) == []


def test_a_plan_ending_with_a_hold_at_its_last_point_has_its_circle_checked() -> None:
    # Plans from TD end with a hold at the last point (two waypoints at one place): the
    # circle still follows the last leg that moves.
    op = _op(VehicleKind.FIXED_WING)
    last = op.plan.waypoints[-1]
    held = dataclasses.replace(
        op.plan, waypoints=(*op.plan.waypoints, dataclasses.replace(last, t_s=END_T_S + 5.0))
    )
    (c,) = plan_vs_geofences(held, op, (FENCE,), FRAME, MonitoringConfig())
    assert c.geofence_id == "F" and c.entry_t_s > END_T_S


def _entry_op() -> Operation:
    """Eastbound at 22.7 m/s (a 76 m turn at 35 degrees), ending at (0, 0) at t = 20 s."""
    op = operation("A", [(-1135.0, 0.0, 100.0, -30.0), (0.0, 0.0, 100.0, END_T_S)], fg=10, ov=10)
    return dataclasses.replace(op, vehicle_kind=VehicleKind.FIXED_WING, cruise_speed_mps=22.7)


# 172 m from the end point, to the right (south) of the eastbound last leg and a little
# ahead: its edge is 132 m out, clear of the 90 m circle (turn radius plus tracking error),
# but the entry from the centre swings out to about 150 m on that side
# (enc_3_0443_endpoint_vertical: a fence 114 m from the end, entered for 3.15 s).
ENTRY_FENCE = cylinder("E", (85.0, -150.0), 40.0)
# The same fence on the left, a little behind: the entry never goes there.
BEHIND_FENCE = cylinder("B", (-85.0, 150.0), 40.0)


def test_a_fence_in_the_entry_onto_the_circle_is_not_clear_of_the_plan() -> None:
    op = _entry_op()
    cfg = MonitoringConfig()
    (c,) = plan_vs_geofences(op.plan, op, (ENTRY_FENCE, BEHIND_FENCE), FRAME, cfg)
    assert c.geofence_id == "E" and END_T_S < c.entry_t_s < END_T_S + 15.0


def test_the_end_ring_is_kept_while_the_plan_stays_and_redone_when_it_changes() -> None:
    # Monitoring checks the ring every cycle of the plan's last horizon: it is integrated
    # once per plan (per points array of the Monitor's projection), never changed in place.
    pts = plan_local(_entry_op().plan, FRAME)
    rings = EndRings()
    first = rings.ring(OperationId("A"), pts, 90.0, 80.0)
    assert first is not None and np.array_equal(first, end_ring(pts, 90.0, 80.0))
    assert rings.ring(OperationId("A"), pts, 90.0, 80.0) is first
    with pytest.raises(ValueError):
        first[0, 0] = 0.0
    moved = pts.copy()
    moved[-1, 1] += 50.0  # a new plan: a new array
    again = rings.ring(OperationId("A"), moved, 90.0, 80.0)
    assert again is not first and np.array_equal(again, end_ring(moved, 90.0, 80.0))
    assert rings.ring(OperationId("A"), moved, 95.0, 80.0) is not again  # other radius
    rings.prune({OperationId("B")})
    assert len(rings) == 0


def test_a_monitor_flags_the_circle_on_every_cycle_with_its_ring_kept() -> None:
    mon = Monitor(FRAME, MonitoringConfig(conformance_time_tolerance_s=1000.0))
    snap = _snapshot(_op(VehicleKind.FIXED_WING))
    (t1,) = mon.cycle(snap)
    mon.cycle(snap)
    (t2,) = mon.active()
    assert t2.id == t1.id and t2.predicted_event_at_s == t1.predicted_event_at_s
