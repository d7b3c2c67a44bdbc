"""An airborne UAS is traffic from take-off to landing, whatever its plan says: a multirotor
whose plan has ended hovers at its end point, and TD's traffic, verification and
compatibility, and so EM, take it there (issue 30 class 1)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import loitering
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    Maneuver,
    Operation,
    OperationId,
    OperationState,
    Threat,
    ThreatKind,
    Track,
    TrackId,
)

T0 = sc.T0_S
ALT_M = 100.0
MEET_S = 60.0  # M passes over H's end point this long after the snapshot
H, M = OperationId("H"), OperationId("M")


def _hover_scene(*, airborne: bool = True) -> tuple[AirspaceSnapshot, Threat]:
    """H, a multirotor, ended its plan at the origin 30 s ago and hovers there; M flies west to
    east through the origin at H's altitude, MEET_S from now. The threat is Monitoring's
    prediction from the tracks (the plans do not show it: H's has ended)."""
    h = sc.make_operation("H", [(-300.0, 0.0, ALT_M), (0.0, 0.0, ALT_M)], t0_s=T0 - 60.0)
    h = replace(h, state=OperationState.ENDED)  # (what a waypoint-time notion would say)
    m = sc.make_operation("M", [(-600.0, 0.0, ALT_M), (600.0, 0.0, ALT_M)], t0_s=T0)
    assert h.plan.end_t_s < T0 and m.plan.start_t_s <= T0 + MEET_S <= m.plan.end_t_s
    snap = sc.snapshot([h, m])
    if airborne:
        snap = replace(snap, airborne=frozenset({H, M}))
    return snap, sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["M", "H"], event_in_s=MEET_S)


def test_an_airborne_uas_after_its_plan_is_traffic_hovering_at_its_end_point() -> None:
    snap, _ = _hover_scene()
    until = T0 + 300.0
    others = loitering.traffic(snap, {M}, sc.FRAME, until, (OperationState.ENDED,))
    assert [o.id for o in others] == [H]
    plan = others[0].plan
    assert plan.end_t_s == until
    lp = plan_to_local(plan, sc.FRAME)
    e, n, z = lp.coords(np.array([T0, T0 + MEET_S, until]))
    assert np.allclose(np.hypot(e, n), 0.0, atol=1e-3) and np.allclose(z, ALT_M)
    # On the ground (or no vehicle state), an ended operation is not traffic.
    grounded, _ = _hover_scene(airborne=False)
    assert loitering.traffic(grounded, {M}, sc.FRAME, until, (OperationState.ENDED,)) == []


def test_td_verification_flags_a_plan_through_a_hovering_uas() -> None:
    snap, _ = _hover_scene()
    td = sc.build_manager().td
    m = snap.operations[M]
    flags = td.verify(m.plan, m, td.others(snap, {M}), ())
    assert any("separation with H" in f for f in flags), flags
    grounded, _ = _hover_scene(airborne=False)
    assert td.verify(m.plan, m, td.others(grounded, {M}), ()) == []


def test_a_uas_crossing_a_hovering_uas_is_moved_not_kept() -> None:
    """Issue 30's closest passes: EM kept both plans ("all_kept") because H's plan had ended.
    Now H hovers (rigid, as a loitering fixed wing) and M is moved clear of it."""
    snap, los = _hover_scene()
    em = sc.build_manager()
    d = em.on_threat(los, snap)
    by_op = {r.operation_id: r for r in d.recommendations}
    audit = next(a for a in d.audit if a.action == "decision")
    rec = by_op.get(M)
    assert rec is not None, audit.detail
    assert "all_kept" not in audit.detail
    assert rec.selected is not None and rec.selected.maneuver is not Maneuver.KEEP_PLAN
    assert H not in by_op  # the hovering UAS is not re-planned
    assert rec.selected.plan is not None
    a = plan_to_local(rec.selected.plan, sc.FRAME)
    t = np.arange(T0 + 20.0, a.t[-1], 0.5)
    ae, an, az = a.coords(t)
    h_min, v_min = em.td.monitoring.effective_minima(10.0, 10.0)
    assert (np.maximum(np.hypot(ae, an) / h_min, np.abs(az - ALT_M) / v_min) >= 1.0).all()


def test_an_airborne_alternative_hovers_after_its_end_in_compatibility() -> None:
    """Two alternatives whose plans never overlap in time are compatible unless the one that
    ends first is airborne: then it hovers at its end point, where the other passes."""
    snap, _ = _hover_scene()
    td = sc.build_manager().td
    early = sc.make_operation("H", [(-300.0, 0.0, ALT_M), (0.0, 0.0, ALT_M)], t0_s=T0)
    late = sc.make_operation("M", [(-600.0, 0.0, ALT_M), (600.0, 0.0, ALT_M)], t0_s=T0 + 40.0)
    snap = replace(snap, operations={H: early, M: late})
    a, b = _keep(early), _keep(late)
    assert early.plan.end_t_s < late.plan.start_t_s
    assert not td.compatible(a, b, snap)
    assert td.compatible(a, b, replace(snap, airborne=frozenset({M})))


def _keep(op: Operation) -> Alternative:
    return Alternative(
        operation_id=op.id, maneuver=Maneuver.KEEP_PLAN, plan=op.plan, cost=0, risk=0
    )


def test_an_airborne_uas_waiting_for_its_plan_is_traffic_where_it_is() -> None:
    """W took off early and waits in the air at the origin for its plan, which starts 500 m
    east in 120 s (it leaves at 70 s at its 10 m/s); M passes over the origin in MEET_S: W is
    traffic there, not nowhere."""
    w = sc.make_operation("W", [(500.0, 0.0, ALT_M), (1000.0, 0.0, ALT_M)], t0_s=T0 + 120.0)
    m = sc.make_operation("M", [(-600.0, 0.0, ALT_M), (600.0, 0.0, ALT_M)], t0_s=T0)
    track = Track(
        id=TrackId("tW"),
        t_s=T0,
        lat_deg=sc.FRAME.point_to_wgs84(0.0, 0.0)[0],
        lon_deg=sc.FRAME.point_to_wgs84(0.0, 0.0)[1],
        alt_amsl_m=ALT_M,
        east_m=0.0,
        north_m=0.0,
        vel_enu_mps=(0.0, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=w.id,
    )
    snap = replace(sc.snapshot([w, m]), tracks={track.id: track})
    td = sc.build_manager().td
    air = replace(snap, airborne=frozenset({w.id, M}))
    assert any("separation with W" in f for f in td.verify(m.plan, m, td.others(air, {M}), ()))
    assert td.verify(m.plan, m, td.others(snap, {M}), ()) == []  # not known to be airborne


def test_a_candidate_of_an_airborne_uas_hovers_after_its_end_in_every_decision() -> None:
    """M's plan ends at the origin in 60 s, where it will hover; X passes there at 100 s. The
    verification of M's plan sees it, on whatever snapshot TD decides (a single-UAS or an
    intruder decision takes the traffic first, as a multi-UAS one does)."""
    m = sc.make_operation("M", [(-600.0, 0.0, ALT_M), (0.0, 0.0, ALT_M)], t0_s=T0)
    x = sc.make_operation("X", [(0.0, -1000.0, ALT_M), (0.0, 1000.0, ALT_M)], t0_s=T0)
    td = sc.build_manager().td
    for airborne, flagged in ((frozenset({M}), True), (frozenset(), False), ({M}, True)):
        snap = replace(sc.snapshot([m, x]), airborne=frozenset(airborne))
        flags = td.verify(m.plan, m, td.others(snap, {M}), ())
        assert any("separation with X" in f for f in flags) is flagged, (airborne, flags)
