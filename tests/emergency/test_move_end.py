"""Two aircraft waiting after their plans with end points that clash (issue 30 class 1, "two
fixed wings circling after their plans"): EM moves one end point away from traffic, instead
of holding a fixed wing (which circles where it is) or warning."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.emergency.endpoint import end_xyz, ends_clash
from gcs_utm.core.tracking import loiter
from gcs_utm.model import (
    AirspaceSnapshot,
    Maneuver,
    Operation,
    OperationId,
    ThreatKind,
    Track,
    TrackId,
    VehicleKind,
)

T0 = sc.T0_S
SPEED_MPS = 18.0
ALT_M = 100.0
F1, F2 = OperationId("F1"), OperationId("F2")


def _circling(name: str, end_e: float, priority: int) -> tuple[Operation, Track]:
    """A fixed wing whose plan (from the west) ended at (end_e, 0) 60 s ago; its track on its
    circle, due north of the centre, heading east (clockwise)."""
    op = replace(
        sc.make_operation(
            name,
            [(end_e - 2000.0, 0.0, ALT_M), (end_e, 0.0, ALT_M)],
            t0_s=T0 - 171.0,
            priority=priority,
            ov_m=25.0,
            speed_mps=SPEED_MPS,
        ),
        vehicle_kind=VehicleKind.FIXED_WING,
        cruise_speed_mps=SPEED_MPS,
    )
    r = loiter.loiter_radius_m(op)
    lat, lon = sc.FRAME.point_to_wgs84(end_e, r)
    track = Track(
        id=TrackId(f"t{name}"),
        t_s=T0,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=ALT_M,
        east_m=end_e,
        north_m=r,
        vel_enu_mps=(SPEED_MPS, 0.0, 0.0),
        position_sigma_m=2.0,
        cooperative=True,
        operation_id=op.id,
    )
    return op, track


def _scene() -> AirspaceSnapshot:
    f1, t1 = _circling("F1", 0.0, priority=1)
    f2, t2 = _circling("F2", 150.0, priority=5)  # circles 150 m apart: they meet
    assert f1.plan.end_t_s < T0 and f2.plan.end_t_s < T0
    return AirspaceSnapshot(
        t_s=T0,
        operations={f1.id: f1, f2.id: f2},
        tracks={t1.id: t1, t2.id: t2},
        geofences=(),
        airborne=frozenset({F1, F2}),
    )


def test_two_fixed_wings_circling_after_their_plans_get_an_end_point_moved() -> None:
    snap = _scene()
    em = sc.build_manager()
    f1, f2 = snap.operations[F1], snap.operations[F2]
    r = loiter.loiter_radius_m(f1)
    assert ends_clash(em.td, f1, f2, end_xyz(em.td, f1), end_xyz(em.td, f2))
    los = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["F1", "F2"], event_in_s=40.0)
    d = em.on_threat(los, snap)
    by_op = {rec.operation_id: rec for rec in d.recommendations}
    assert set(by_op) == {F1}, [a.detail for a in d.audit]  # the lower priority moves
    alt = by_op[F1].selected
    assert alt is not None and alt.maneuver is Maneuver.MOVE_END and alt.plan is not None
    assert by_op[F1].command is None
    lp = plan_to_local(alt.plan, sc.FRAME)
    here = np.array([0.0, r])  # it leaves from where it is
    assert np.hypot(lp.e[0] - here[0], lp.n[0] - here[1]) < 1.0 and lp.t[0] == T0
    new_end = lp.xyz()[-1]
    moved = replace(f1, plan=alt.plan)
    assert not ends_clash(em.td, moved, f2, new_end, end_xyz(em.td, f2))
    h_m, v_m = em.td.pair_minima(f1, f2)
    far = math.hypot(new_end[0] - 150.0, new_end[1]) >= h_m + 2 * r - 1e-6
    assert far or abs(new_end[2] - ALT_M) >= v_m
    assert any("end point moved" in str(a.detail.get("reason")) for a in d.audit)


def test_no_end_point_is_moved_while_a_plan_still_runs_at_the_loss() -> None:
    snap = _scene()
    em = sc.build_manager()
    # the loss predicted before F2's plan ends: the plans, not their end points, decide it
    f2 = snap.operations[F2]
    late_end = replace(
        f2.plan, waypoints=(*f2.plan.waypoints[:-1], replace(f2.plan.waypoints[-1], t_s=T0 + 100.0))
    )
    snap = replace(snap, operations={**snap.operations, F2: replace(f2, plan=late_end)})
    los = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["F1", "F2"], event_in_s=40.0)
    d = em.on_threat(los, snap)
    assert all(
        r.selected is None or r.selected.maneuver is not Maneuver.MOVE_END
        for r in d.recommendations
    )
