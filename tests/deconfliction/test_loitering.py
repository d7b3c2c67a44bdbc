"""A fixed wing whose plan has ended circles its last waypoint: TD and EM treat it as traffic
on that circle (the one Tracking predicts), not as a point that no longer exists."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import loitering
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.tracking import loiter
from gcs_utm.model import (
    AirspaceSnapshot,
    Maneuver,
    OperationId,
    Threat,
    ThreatKind,
    Track,
    TrackId,
    VehicleKind,
)

T0 = sc.T0_S
SPEED_MPS = 18.0
ALT_M = 100.0
MEET_S = 60.0  # the multirotor crosses the predicted circle this long after the snapshot


def _loitering_scene() -> tuple[AirspaceSnapshot, Threat, float]:
    """F, a fixed wing, ended its plan at the origin 100 s ago and circles it clockwise (its
    track due east of the centre on the circle, heading south); M, a multirotor, flies west
    to east through the point where F will be on its circle in MEET_S."""
    f = replace(
        sc.make_operation("F", [(-2000.0, 0.0, ALT_M), (0.0, 0.0, ALT_M)], t0_s=T0 - 211.0),
        vehicle_kind=VehicleKind.FIXED_WING,
        cruise_speed_mps=SPEED_MPS,
    )
    radius = loiter.loiter_radius_m(f)
    assert radius > 0.0
    track = Track(
        id=TrackId("tF"),
        t_s=T0,
        lat_deg=sc.FRAME.point_to_wgs84(radius, 0.0)[0],
        lon_deg=sc.FRAME.point_to_wgs84(radius, 0.0)[1],
        alt_amsl_m=ALT_M,
        east_m=radius,
        north_m=0.0,
        vel_enu_mps=(0.0, -SPEED_MPS, 0.0),
        position_sigma_m=2.0,
        cooperative=True,
        operation_id=f.id,
    )
    east, north, _ = loiter.loiter_points(
        radius_m=np.array([radius]),
        pos=np.array([[radius, 0.0, ALT_M]]),
        vel=np.array([[0.0, -SPEED_MPS, 0.0]]),
        center=np.array([[0.0, 0.0, ALT_M]]),
        tau_s=np.array([[MEET_S]]),
        decay_s=loitering.CONVERGE_S,
    )
    pe, pn = float(east[0, 0]), float(north[0, 0])
    m = sc.make_operation(
        "M",
        [(pe - 1000.0, pn, ALT_M), (pe + 1000.0, pn, ALT_M)],
        t0_s=T0 + MEET_S - 100.0,
    )
    snap = AirspaceSnapshot(
        t_s=T0, operations={m.id: m, f.id: f}, tracks={track.id: track}, geofences=()
    )
    los = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["M", "F"], event_in_s=MEET_S)
    return snap, los, radius


def test_the_loiter_plan_goes_round_the_tracked_circle() -> None:
    snap, _, radius = _loitering_scene()
    f = snap.operations[OperationId("F")]
    plan = loitering.loiter_plan(f, snap, sc.FRAME, T0 + 300.0)
    assert plan is not None and plan.end_t_s == T0 + 300.0
    lp = plan_to_local(plan, sc.FRAME)
    e, n, z = lp.coords(np.arange(T0, T0 + 300.0, 1.0))  # chords: within CIRCLE_STEP_S sag
    assert np.allclose(np.hypot(e, n), radius, atol=2.5) and np.allclose(z, ALT_M)
    # Clockwise from east: south of the centre a quarter turn later.
    quarter_s = 0.5 * np.pi * radius / SPEED_MPS
    q = lp.position_at(T0 + quarter_s)
    assert abs(q[0]) < 2.5 and q[1] < -radius + 2.5
    # Not loitering: a plan still running, or a track far from the last waypoint.
    assert loitering.loiter_plan(f, replace(snap, t_s=T0 - 150.0), sc.FRAME, T0) is None
    far = {k: replace(t, lat_deg=t.lat_deg + 0.05) for k, t in snap.tracks.items()}
    assert loitering.loiter_plan(f, replace(snap, tracks=far), sc.FRAME, T0 + 300.0) is None


def test_a_multirotor_crossing_a_loitering_fixed_wing_is_moved_not_kept() -> None:
    snap, los, _ = _loitering_scene()
    em = sc.build_manager()
    d = em.on_threat(los, snap)
    by_op = {r.operation_id: r for r in d.recommendations}
    rec = by_op.get(OperationId("M"))
    audit = next(a for a in d.audit if a.action == "decision")
    assert rec is not None, audit.detail
    assert "all_kept" not in audit.detail
    assert rec.selected is not None and rec.selected.maneuver is not Maneuver.KEEP_PLAN
    assert OperationId("F") not in by_op  # the loitering aircraft is not re-planned
    # The multirotor's new plan keeps the minima from F's circle.
    circle = loitering.loiter_plan(snap.operations[OperationId("F")], snap, sc.FRAME, T0 + 600.0)
    assert circle is not None and rec.selected.plan is not None
    a = plan_to_local(rec.selected.plan, sc.FRAME)
    b = plan_to_local(circle, sc.FRAME)
    t = np.arange(T0 + 20.0, min(a.t[-1], b.t[-1]), 0.5)
    (ae, an, az), (be, bn, bz) = a.coords(t), b.coords(t)
    h, v = em.td.monitoring.effective_minima(10.0, 10.0)
    assert (np.maximum(np.hypot(ae - be, an - bn) / h, np.abs(az - bz) / v) >= 1.0).all()
