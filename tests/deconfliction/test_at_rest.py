"""A hovering multirotor whose plan moves on (held by EM): TD starts its new plans where it
is, not where its plan would have taken it by the time it gets them (at_rest.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction.at_rest import at_rest, waiting_plan
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.model import (
    AirspaceSnapshot,
    Maneuver,
    OperationId,
    ThreatKind,
    Track,
    TrackId,
    VehicleKind,
)

T0 = sc.T0_S
ALT_M = 100.0
SPEED_MPS = 10.0
RECEIPT_S = 2.0  # the vehicle can have a new plan this long after the decision
START_S = 7.0  # new plans start this long after it


def _track(east_m: float, north_m: float, vel: tuple[float, float, float]) -> Track:
    lat, lon = sc.FRAME.point_to_wgs84(east_m, north_m)
    return Track(
        id=TrackId("tH"),
        t_s=T0,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=ALT_M,
        east_m=east_m,
        north_m=north_m,
        vel_enu_mps=vel,
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=OperationId("H"),
    )


def _scene(vel: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> AirspaceSnapshot:
    """H, a multirotor held at the origin (its plan, re-timed there, flies on east at 10 m/s);
    O flies head-on towards it 30 m higher, a loss predicted in 40 s."""
    h = sc.make_operation("H", [(0.0, 0.0, ALT_M), (1500.0, 0.0, ALT_M)], t0_s=T0)
    o = sc.make_operation("O", [(800.0, 0.0, ALT_M + 5.0), (-700.0, 0.0, ALT_M + 5.0)], t0_s=T0)
    tr = _track(0.0, 0.0, vel)
    return AirspaceSnapshot(t_s=T0, operations={h.id: h, o.id: o}, tracks={tr.id: tr}, geofences=())


def test_a_held_multirotor_waits_where_it_is_until_it_can_have_a_plan() -> None:
    snap = _scene()
    h = snap.operations[OperationId("H")]
    plan = waiting_plan(h, snap, sc.FRAME, T0 + RECEIPT_S)
    assert plan is not None
    lp = plan_to_local(plan, sc.FRAME)
    assert np.allclose(lp.position_at(T0 + RECEIPT_S)[:2], 0.0, atol=0.01)
    # then on along its plan, late by the wait
    assert np.allclose(lp.position_at(T0 + RECEIPT_S + 10.0)[:2], (100.0, 0.0), atol=0.1)
    # Left alone: a UAS that moves, a fixed wing, a plan that does not move now.
    assert waiting_plan(h, _scene((SPEED_MPS, 0.0, 0.0)), sc.FRAME, T0 + RECEIPT_S) is None
    fw = replace(h, vehicle_kind=VehicleKind.FIXED_WING)
    assert waiting_plan(fw, replace(snap, operations={h.id: fw}), sc.FRAME, T0 + 2.0) is None
    assert waiting_plan(h, replace(snap, t_s=T0 + 1000.0), sc.FRAME, T0 + 1002.0) is None
    assert at_rest(snap, sc.FRAME, None, None) is snap


def test_new_plans_of_a_held_multirotor_start_where_it_is() -> None:
    snap = _scene()
    td = sc.build_manager().td
    los = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["H", "O"], event_in_s=40.0)
    out = td.resolve_loss_of_separation(
        los, snap, start_t_s=T0 + START_S, lead_in_from_t_s=T0 + RECEIPT_S
    )
    moved = [a for a in out[OperationId("H")] if a.maneuver is not Maneuver.KEEP_PLAN and a.plan]
    assert moved, td.dropped
    for alt in moved:
        assert alt.plan is not None
        lp = plan_to_local(alt.plan, sc.FRAME)
        # The vehicle is still at the origin when it gets the plan; without the wait the plan
        # had it 20 m east by then (70 m by the start), and it flew behind it.
        first = lp.position_at(T0 + RECEIPT_S)
        assert float(np.hypot(first[0], first[1])) < 1.0, alt.maneuver
        start = lp.position_at(T0 + START_S)
        assert float(np.hypot(start[0], start[1])) <= SPEED_MPS * (START_S - RECEIPT_S) + 1.0
