"""A plan whose destination lies inside an active geofence gets a reroute that ends outside
it (for a fixed wing, its loiter circle outside too): reroute, direct to goal and next
waypoint all lead into the fence, and before this nothing was offered (a fixed wing bound
for a point inside a fence was told to hold and circled through the traffic around it,
enc_1_0076_fence_head_on)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_geofences
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    GeofenceId,
    Maneuver,
    Operation,
    OperationId,
    ThreatKind,
    VehicleKind,
)

MON = MonitoringConfig()
RADIUS_M = 40.0


def _fenced_goal(
    kind: VehicleKind, speed_mps: float
) -> tuple[list[Alternative], Operation, AirspaceSnapshot]:
    fence = sc.cylinder("F", 0.0, 0.0, RADIUS_M)
    op = sc.make_operation("A", [(-1500, 0, 100), (8, 5, 100)], speed_mps=speed_mps, ov_m=25.0)
    op = replace(op, vehicle_kind=kind)
    t = sc.T0_S + 20.0
    snap = AirspaceSnapshot(t_s=t, operations={op.id: op}, tracks={}, geofences=(fence,))
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["A"], t_s=t, geofence_id=GeofenceId("F"))
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(min_height_above_home_m=0.0), MON)
    alts = td.resolve_single(threat, OperationId("A"), snap)
    return alts, op, snap


def test_a_destination_inside_a_fence_gets_an_end_point_outside_it() -> None:
    for kind, speed in ((VehicleKind.MULTIROTOR, 8.0), (VehicleKind.FIXED_WING, 20.0)):
        alts, op, snap = _fenced_goal(kind, speed)
        got = [a for a in alts if a.maneuver is Maneuver.REROUTE]
        assert got, kind
        a = got[0]
        assert a.plan is not None
        assert plan_vs_geofences(a.plan, op, snap.geofences, sc.FRAME, MON) == []
        lp = plan_to_local(a.plan, sc.FRAME)
        end_m = float(np.hypot(lp.e[-1], lp.n[-1]))
        env = op.performance()
        circle_m = 0.0 if env.can_hover else env.turn_radius_m
        # outside the fence grown by the volume, and the loiter circle with it
        assert end_m - circle_m >= RADIUS_M + op.operational_volume_m, (kind, end_m)
        # the closest point outside, not anywhere: on the side the destination is nearest
        assert end_m - circle_m < RADIUS_M + op.operational_volume_m + 40.0, (kind, end_m)


def test_a_fixed_wing_whose_end_circle_enters_a_fence_gets_an_end_point_clear_of_it() -> None:
    """The destination lies outside the fence grown by the volume (100 m from its centre,
    65 m needed) but the 80 m circle the fixed wing flies round it once its plan has ended
    comes within 20 m of the centre: every route to it ends inside the fence, so the end
    point moves until the circle clears it (enc_7_0003_endpoint_vertical)."""
    fence = sc.cylinder("F", 0.0, 0.0, RADIUS_M)
    op = sc.make_operation("A", [(1500, 0, 100), (100, 0, 100)], speed_mps=20.0, ov_m=25.0)
    op = replace(op, vehicle_kind=VehicleKind.FIXED_WING)
    t = sc.T0_S + 20.0
    snap = AirspaceSnapshot(t_s=t, operations={op.id: op}, tracks={}, geofences=(fence,))
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["A"], t_s=t, geofence_id=GeofenceId("F"))
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(min_height_above_home_m=0.0), MON)
    alts = td.resolve_single(threat, OperationId("A"), snap)
    circle_m = op.performance().turn_radius_m
    ends = []
    for a in alts:
        if a.maneuver is Maneuver.REROUTE and a.plan is not None:
            lp = plan_to_local(a.plan, sc.FRAME)
            ends.append(float(np.hypot(lp.e[-1], lp.n[-1])))
    assert ends, [(a.maneuver, a.detail) for a in alts]
    end_m = max(ends)
    # the circle round the new end clears the fence grown by the volume, and no more than
    # needed (on the side the destination was)
    assert end_m - circle_m >= RADIUS_M + op.operational_volume_m, end_m
    assert end_m - circle_m < RADIUS_M + op.operational_volume_m + 40.0, end_m


def test_a_fixed_wing_whose_entry_onto_its_end_circle_enters_a_fence_gets_it_clear() -> None:
    """The destination is 160 m south of the fence's centre: the 80 m circle round it keeps
    80 m from the fence (65 m needed), but the aircraft arrives westbound at 22.7 m/s and
    its entry from the centre swings out about 150 m to its right, north, into the fence
    (enc_3_0443_endpoint_vertical). The end point moves until the entry clears it, and the
    plan TD offers is clear of the fence as Monitoring checks it (the same entry)."""
    fence = sc.cylinder("F", 0.0, 0.0, RADIUS_M)
    op = sc.make_operation("A", [(1500, -160, 100), (0, -160, 100)], speed_mps=22.7, ov_m=25.0)
    op = replace(op, vehicle_kind=VehicleKind.FIXED_WING)
    t = sc.T0_S + 20.0
    snap = AirspaceSnapshot(t_s=t, operations={op.id: op}, tracks={}, geofences=(fence,))
    assert plan_vs_geofences(op.plan, op, (fence,), sc.FRAME, MON)  # the filed plan is not
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["A"], t_s=t, geofence_id=GeofenceId("F"))
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(min_height_above_home_m=0.0), MON)
    alts = td.resolve_single(threat, OperationId("A"), snap)
    moved = [
        a.plan
        for a in alts
        if a.maneuver is Maneuver.REROUTE
        and a.plan is not None
        and a.detail.startswith("end at the closest point outside")
    ]
    assert len(moved) == 1, [(a.maneuver, a.detail) for a in alts]
    lp = plan_to_local(moved[0], sc.FRAME)
    assert float(np.hypot(lp.e[-1], lp.n[-1])) > 160.0 + 20.0  # moved away from the fence
    assert plan_vs_geofences(moved[0], op, (fence,), sc.FRAME, MON) == []
