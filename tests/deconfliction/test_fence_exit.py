"""A held multirotor whose plan crosses a fence it stopped short of leaves from where it gets
its new plan, not after its plan's lead-in has carried it in (fence_exit.py, issue 30
geofence intrusions: enc_5_0036_fence_head_on)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.model import AirspaceSnapshot, OperationId, ThreatKind, Track, TrackId, VehicleKind

T0 = sc.T0_S
ALT_M = 100.0
RECEIPT_S = 2.0  # the vehicle can have a new plan this long after the decision
START_S = 7.0  # new plans start this long after it
FENCE_E_M, FENCE_R_M = 40.0, 30.0  # its edge 10 m east of the held UAS, inside the grown fence
H = OperationId("H")


def _scene() -> AirspaceSnapshot:
    """H, a multirotor held at the origin; its plan (re-timed there) flies on east at 6 m/s
    straight through the fence."""
    h = sc.make_operation("H", [(0.0, 0.0, ALT_M), (1200.0, 0.0, ALT_M)], t0_s=T0, speed_mps=6.0)
    lat, lon = sc.FRAME.point_to_wgs84(0.0, 0.0)
    tr = Track(
        id=TrackId("tH"),
        t_s=T0,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=ALT_M,
        east_m=0.0,
        north_m=0.0,
        vel_enu_mps=(0.0, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=H,
    )
    fence = sc.cylinder("G1", FENCE_E_M, 0.0, FENCE_R_M)
    return AirspaceSnapshot(t_s=T0, operations={h.id: h}, tracks={tr.id: tr}, geofences=(fence,))


def _deepest_m(snap: AirspaceSnapshot) -> tuple[float, list[float]]:
    """How far inside the fence (m, negative: outside) the deepest point of any alternative
    goes, and the start times of the alternatives."""
    td = sc.build_manager().td
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["H"], event_in_s=3.0, geofence_id="G1")
    alts = td.resolve_single(
        threat, H, snap, start_t_s=T0 + START_S, lead_in_from_t_s=T0 + RECEIPT_S
    )
    assert alts, td.dropped
    deepest = -np.inf
    starts = []
    for a in alts:
        assert a.plan is not None
        lp = plan_to_local(a.plan, sc.FRAME)
        starts.append(float(lp.t[0]))
        # the path as flown, sampled every 0.25 s (lead-in included)
        t = np.arange(lp.t[0], lp.t[-1], 0.25)
        e, n, _ = lp.coords(t)
        inside = FENCE_R_M - np.hypot(e - FENCE_E_M, n)
        deepest = max(deepest, float(inside.max()))
    return deepest, starts


def test_a_held_multirotor_leaves_from_where_it_gets_the_plan() -> None:
    """Every way out (escape, hold outside, return home) starts at the earliest receipt from
    where H is and never enters the fence; with its plan's lead-in it went 5 m inside."""
    deepest, starts = _deepest_m(_scene())
    assert deepest < 0.0, f"a way out enters the fence by {deepest:.1f} m"
    assert np.allclose(starts, T0 + RECEIPT_S)


def test_a_fixed_wing_keeps_its_start_ahead() -> None:
    """A fixed wing flies on whatever it is told: its new plans still start ahead, with the
    lead-in from the earliest receipt."""
    snap = _scene()
    fw = replace(snap.operations[H], vehicle_kind=VehicleKind.FIXED_WING)
    td = sc.build_manager().td
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["H"], event_in_s=3.0, geofence_id="G1")
    alts = td.resolve_single(
        threat,
        H,
        replace(snap, operations={H: fw}),
        start_t_s=T0 + START_S,
        lead_in_from_t_s=T0 + RECEIPT_S,
    )
    assert alts, td.dropped
    for a in alts:
        assert a.plan is not None
        assert np.isclose(plan_to_local(a.plan, sc.FRAME).t, T0 + START_S).any()
