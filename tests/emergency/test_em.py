"""Emergency Management: policies, recommendation lifecycle, joint selection, audit."""

from __future__ import annotations

from dataclasses import replace

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager, select_joint
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_geofences, strategic_check
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    CommandKind,
    GeofenceKind,
    Maneuver,
    OperationId,
    Position,
    RecommendationState,
    ThreatKind,
    ThreatStatus,
    Track,
    TrackId,
)

MON = MonitoringConfig()


def make_em(**cfg: object) -> EmergencyManager:
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    return EmergencyManager(sc.FRAME, EmergencyConfig(**cfg), td, MON)  # type: ignore[arg-type]


def at(snap: AirspaceSnapshot, t_s: float) -> AirspaceSnapshot:
    return replace(snap, t_s=t_s)


def _offset_m(snap: AirspaceSnapshot, alt: Alternative) -> float:
    """Farthest 3D distance of an alternative's path from the operation's plan."""
    from gcs_utm.core.deconfliction.geometry import plan_to_local
    from gcs_utm.core.deconfliction.scoring import distance_to_polyline

    assert alt.plan is not None
    new = plan_to_local(alt.plan, sc.FRAME).xyz()
    old = plan_to_local(snap.operations[alt.operation_id].plan, sc.FRAME).xyz()
    return float(distance_to_polyline(new, old).max())


def test_loss_of_separation_recommends_a_jointly_conflict_free_plan_and_audits_it() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    d = em.on_threat(threat, snap)
    assert d.recommendations and not d.escalations
    by_op = {r.operation_id: r for r in d.recommendations}
    # Priorities: A (priority 1) moves; B (priority 2) keeps its plan or moves less than A.
    rec = by_op[OperationId("A")]
    assert rec.selected is not None and rec.selected.maneuver is not Maneuver.KEEP_PLAN
    if OperationId("B") in by_op:
        b_sel = by_op[OperationId("B")].selected
        assert b_sel is not None
        assert _offset_m(snap, b_sel) < _offset_m(snap, rec.selected)
    assert rec.state is RecommendationState.PROPOSED
    # The event is 100 s ahead: the deadline is the answer window (20 s), not event - 10 s.
    assert rec.deadline_t_s - snap.t_s == pytest.approx(20.0, abs=1e-6)
    ops = dict(snap.operations)
    for r in d.recommendations:
        assert r.selected is not None
        ops[r.operation_id] = replace(ops[r.operation_id], plan=r.selected.plan)
    assert strategic_check(list(ops.values()), (), sc.FRAME, MON).conflicts == ()
    # Alternatives shown to the pilot are also compatible with the others' selection.
    for r in d.recommendations:
        mine = ops[r.operation_id]
        for alt in r.alternatives:
            ops[r.operation_id] = replace(mine, plan=alt.plan)
            assert strategic_check(list(ops.values()), (), sc.FRAME, MON).conflicts == ()
        ops[r.operation_id] = mine
    audit = d.audit[0]
    assert (
        audit.action == "decision" and audit.detail["alpha"] == 1.0 and audit.detail["beta"] == 3.0
    )
    alts = audit.detail["alternatives"]
    assert isinstance(alts, list) and len(alts) >= 10
    assert {"cost", "risk", "score", "maneuver", "operation_id"} <= set(alts[0])
    selected = audit.detail["selected"]
    assert isinstance(selected, dict)
    assert selected["A"] == rec.selected.maneuver.value
    assert selected["B"] == (
        by_op[OperationId("B")].selected.maneuver.value  # type: ignore[union-attr]
        if OperationId("B") in by_op
        else "keep_plan"
    )


def test_rejection_replans_without_the_rejected_maneuver() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    rec = em.on_threat(threat, snap).recommendations[0]
    first = rec.selected.maneuver  # type: ignore[union-attr]
    d = em.on_answer(rec, False, snap)
    assert any(
        r.state is RecommendationState.REJECTED and r.version == 1 for r in d.recommendations
    )
    new = [r for r in d.recommendations if r.state is RecommendationState.PROPOSED]
    assert new, "a rejection is re-planned"
    for r in new:
        assert r.selected is not None
        if r.operation_id == rec.operation_id:
            assert r.version == 2 and r.selected.maneuver is not first
    assert d.audit[0].action == "rejected"


def test_repeated_rejection_escalates_to_the_operator() -> None:
    snap, threat = sc.scenario_geofence_reroute(20)
    em = make_em(max_replans=1)
    rec = em.on_threat(threat, snap).recommendations[0]
    d = em.on_answer(rec, False, snap)
    (again,) = [r for r in d.recommendations if r.state is RecommendationState.PROPOSED]
    assert again.version == 2 and again.selected is not None
    assert again.selected.maneuver is not rec.selected.maneuver  # type: ignore[union-attr]
    d2 = em.on_answer(again, False, snap)
    assert d2.escalations and "operator action needed" in d2.escalations[0]
    # no third plan: the escalation proposes the safe command (hold) instead
    (cmd,) = em.pending()
    assert cmd.selected is None and cmd.command is not None
    assert cmd.command.kind is CommandKind.HOLD and "hold proposed" in d2.escalations[0]


def test_stale_answer_is_ignored_with_a_warning() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    rec = em.on_threat(threat, snap).recommendations[0]
    d = em.on_answer(replace(rec, version=rec.version + 5), True, snap)
    assert d.warnings and not d.recommendations
    assert em.recommendation(rec.id).state is RecommendationState.PROPOSED  # type: ignore[union-attr]


def test_accept_then_threat_closed_keeps_the_accepted_one() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    recs = em.on_threat(threat, snap).recommendations
    for rec in recs:
        d = em.on_answer(rec, True, snap)
        assert d.recommendations[0].state is RecommendationState.ACCEPTED
    closed = em.on_threat_closed(replace(threat, status=ThreatStatus.CLOSED))
    assert closed.superseded == ()
    for rec in recs:
        assert em.recommendation(rec.id).state is RecommendationState.ACCEPTED  # type: ignore[union-attr]


def test_a_closed_threat_is_audited_with_why_it_closed() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    em.on_threat(threat, snap)
    why = "closed: operation B landed"
    d = em.on_threat_closed(replace(threat, status=ThreatStatus.CLOSED, message=why))
    (entry,) = [a for a in d.audit if a.action == "threat_closed"]
    assert entry.subject == threat.id and entry.detail["reason"] == why


def test_expiry_escalates_and_replans_and_closing_supersedes_the_new_version() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    rec = em.on_threat(threat, snap).recommendations[0]
    late = at(snap, rec.deadline_t_s + 1.0)
    d = em.on_expired(rec, late)
    assert any(r.state is RecommendationState.EXPIRED for r in d.recommendations)
    assert d.escalations and "expired" in d.escalations[0]
    pending = em.pending()
    assert pending, "an expired recommendation is re-planned, not dropped"
    closed = em.on_threat(replace(threat, status=ThreatStatus.CLOSED), late)
    assert set(closed.superseded) == {r.id for r in pending}
    assert em.pending() == []


def test_a_persisting_threat_does_not_churn_recommendations() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    first = em.on_threat(threat, snap).recommendations
    assert first
    again = em.on_threat(replace(threat, status=ThreatStatus.UPDATED), at(snap, snap.t_s + 1))
    assert again.recommendations == ()
    assert [r.id for r in em.pending()] == [r.id for r in first]


def test_no_feasible_alternative_is_an_explicit_escalation() -> None:
    # Two UAS above the immovable priority, head-on: nothing may move.
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=2000)
    b = sc.make_operation("B", [(1000, 0, 100), (-1000, 0, 100)], priority=2000)
    em = make_em()
    d = em.on_threat(sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"]), sc.snapshot([a, b]))
    assert all(r.selected is None for r in d.recommendations)  # no plan...
    assert d.escalations and "no conflict-free combination" in d.escalations[0]
    assert d.audit[0].action == "escalation"
    # ...but the escalation carries an immediate command, for the pilot to confirm
    (cmd,) = d.recommendations
    assert cmd.command is not None and cmd.state is RecommendationState.PROPOSED
    assert f"{cmd.command.kind.value} for {cmd.operation_id} proposed" in d.escalations[0]


def test_an_escalated_threat_is_retried_only_after_the_retry_period() -> None:
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=2000)
    b = sc.make_operation("B", [(1000, 0, 100), (-1000, 0, 100)], priority=2000)
    snap = sc.snapshot([a, b])
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"])
    em = make_em(retry_after_s=30.0)
    first = em.on_threat(threat, snap)
    assert first.escalations
    updated = replace(threat, status=ThreatStatus.UPDATED)
    assert em.on_threat(updated, at(snap, snap.t_s + 1.0)) == Decision()  # no churn
    # the pilot refuses the proposed command: the case waits for the retry period
    (cmd,) = first.recommendations
    assert em.on_answer(cmd, False, at(snap, snap.t_s + 2.0)).escalations
    assert em.on_threat(updated, at(snap, snap.t_s + 3.0)) == Decision()
    again = em.on_threat(updated, at(snap, snap.t_s + 31.0))
    assert again.escalations, "still unsolvable: the operator is reminded"


def test_jamming_suspends_creates_a_geofence_and_reroutes_the_neighbour() -> None:
    """The paper's use case 2: A is jammed at (0, 0); B's plan passes 30 m from it."""
    a = sc.make_operation("A", [(-500, 0, 100), (500, 0, 100)])
    b = sc.make_operation("B", [(-1500, 30, 130), (1500, 30, 130)], priority=2)
    t = sc.T0_S + 50.0
    snap = sc.snapshot([a, b], t_s=t)
    la, lo = sc.FRAME.point_to_wgs84(0.0, 0.0)
    threat = sc.threat(
        ThreatKind.JAMMING_ATTACK,
        ["A"],
        t_s=t,
        position=Position(lat_deg=la, lon_deg=lo, alt_amsl_m=100.0),
    )
    em = make_em()
    d = em.on_threat(threat, snap)
    # Suspend A (hold) as a recommendation, not an order: no command without autonomous mode.
    hold = next(r for r in d.recommendations if r.operation_id == "A")
    assert hold.command is not None and hold.command.kind is CommandKind.HOLD
    assert d.commands == ()
    # A dynamic geofence of the configured radius and band around A, active from now; it
    # does not apply to A itself (A is suspended inside it, not intruding).
    (fence,) = d.geofences
    cfg = EmergencyConfig()
    assert fence.kind is GeofenceKind.DYNAMIC and fence.radius_m == cfg.jamming_radius_m
    assert fence.min_alt_amsl_m == pytest.approx(100.0 - cfg.jamming_band_m)
    assert fence.max_alt_amsl_m == pytest.approx(100.0 + cfg.jamming_band_m)
    assert fence.start_t_s == t and fence.end_t_s == t + cfg.jamming_duration_s
    assert hold.new_geofence == fence and fence.exempt == ("A",)
    # B is rerouted around it, and the new plan is clean for Monitoring.
    reroute = next(r for r in d.recommendations if r.operation_id == "B")
    assert reroute.selected is not None and reroute.selected.plan is not None
    assert plan_vs_geofences(b.plan, b, [fence], sc.FRAME, MON)  # the old plan crosses
    assert plan_vs_geofences(reroute.selected.plan, b, [fence], sc.FRAME, MON) == []


def test_autonomous_mode_applies_without_confirmation() -> None:
    a = sc.make_operation("A", [(-500, 0, 100), (500, 0, 100)])
    snap = sc.snapshot([a], t_s=sc.T0_S + 10)
    threat = sc.threat(ThreatKind.SPOOFING_ATTACK, ["A"], t_s=sc.T0_S + 10)
    d = make_em(autonomous=True, suspend_command="land").on_threat(threat, snap)
    assert [c.kind for c in d.commands] == [CommandKind.LAND]
    assert all(r.state is RecommendationState.ACCEPTED for r in d.recommendations)


def test_low_battery_goes_to_the_nearest_landing_site_or_lands_now() -> None:
    op = sc.make_operation(
        "A", [(0, 0, 100), (3000, 0, 100)], landing_sites=[(1400, 300, 60)], endurance_s=300.0
    )
    # 1000 m out: home is 100 s back, the site 50 s away and 27 s down (40 m at 1.5 m/s)
    t = sc.T0_S + 100.0
    threat = sc.threat(ThreatKind.LACK_OF_BATTERY, ["A"], t_s=t)
    d = make_em().on_threat(threat, sc.snapshot([op], t_s=t))
    (rec,) = d.recommendations
    assert rec.selected is not None and rec.selected.maneuver is Maneuver.LANDING_SITE
    assert [a.maneuver for a in rec.alternatives] == [Maneuver.RETURN_HOME]
    starved = replace(op, endurance_s=110.0)
    d2 = make_em().on_threat(threat, sc.snapshot([starved], t_s=t))
    (land,) = d2.recommendations
    assert land.command is not None and land.command.kind is CommandKind.LAND
    assert d2.escalations


def test_wildfire_alert_becomes_a_geofence_and_reroutes_who_crosses_it() -> None:
    op = sc.make_operation("A", [(-1500, 0, 100), (1500, 0, 100)])
    fire = sc.cylinder("fire", 0.0, 0.0, 200.0)
    threat = sc.threat(ThreatKind.ALERT_WARNING, [], area=fire, message="wildfire")
    d = make_em().on_threat(threat, sc.snapshot([op]))
    assert [g.id for g in d.geofences] == ["fire"]
    assert d.geofences[0].kind is GeofenceKind.DYNAMIC and d.geofences[0].end_t_s is not None
    (rec,) = d.recommendations
    assert rec.operation_id == "A" and rec.selected is not None
    assert plan_vs_geofences(rec.selected.plan, op, d.geofences, sc.FRAME, MON) == []  # type: ignore[arg-type]


def test_in_contingency_volume_only_warns() -> None:
    op = sc.make_operation("A", [(0, 0, 100), (1000, 0, 100)])
    d = make_em().on_threat(sc.threat(ThreatKind.UAS_IN_CV, ["A"]), sc.snapshot([op]))
    assert d.warnings and d.recommendations == () and d.escalations == ()


def test_a_sysid_claim_only_warns_gnss_spoofing_still_suspends() -> None:
    """A second sender on the vehicle's system id (SYSID_CONFLICT) leaves the vehicle flying,
    even in autonomous mode; the vehicle's own GNSS spoofing is still suspended."""
    a = sc.make_operation("A", [(-500, 0, 100), (500, 0, 100)])
    snap = sc.snapshot([a], t_s=sc.T0_S + 10)
    claim = sc.threat(ThreatKind.SYSID_CONFLICT, ["A"], t_s=sc.T0_S + 10, message="claimed")
    d = make_em(autonomous=True).on_threat(claim, snap)
    assert d.commands == () and d.recommendations == () and d.geofences == ()
    assert d.warnings == ("SYSID_CONFLICT: A claimed",) and d.escalations == ()
    assert [e.action for e in d.audit] == ["warn"]
    spoof = sc.threat(ThreatKind.SPOOFING_ATTACK, ["A"], t_s=sc.T0_S + 10)
    d2 = make_em(autonomous=True).on_threat(spoof, snap)
    assert [c.kind for c in d2.commands] == [CommandKind.HOLD] and d2.geofences


def test_link_loss_alerts_and_fences_the_predicted_position() -> None:
    op = sc.make_operation("A", [(0, 0, 100), (1000, 0, 100)])
    d = make_em().on_threat(sc.threat(ThreatKind.COMMUNICATION_FAILURE, ["A"]), sc.snapshot([op]))
    assert d.escalations and "link lost" in d.escalations[0]
    (fence,) = d.geofences
    e, n = sc.FRAME.point_to_local(fence.center.lat_deg, fence.center.lon_deg)  # type: ignore[union-attr]
    assert (e, n) == pytest.approx((100.0, 0.0), abs=0.5)  # 10 s ahead at 10 m/s


def test_intruder_gets_vertical_avoidance_advice() -> None:
    op = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)])
    lat, lon = sc.FRAME.point_to_wgs84(1000.0, 0.0)
    intruder = Track(
        id=TrackId("icao:abcdef"),
        t_s=sc.T0_S,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=100.0,
        east_m=1000.0,
        north_m=0.0,
        vel_enu_mps=(-20.0, 0.0, 0.0),
        position_sigma_m=5.0,
        cooperative=False,
    )
    snap = AirspaceSnapshot(
        t_s=sc.T0_S, operations={op.id: op}, tracks={intruder.id: intruder}, geofences=()
    )
    threat = sc.threat(ThreatKind.INTRUDER, ["A"], intruder_id=intruder.id)
    d = make_em().on_threat(threat, snap)
    (rec,) = d.recommendations
    assert rec.selected is not None and rec.selected.maneuver in (Maneuver.GO_UP, Maneuver.GO_DOWN)
    assert "intruder" in rec.selected.detail


def test_joint_selection_skips_incompatible_pairs_and_reports_truncation() -> None:
    def alt(op: str, m: Maneuver, cost: float) -> Alternative:
        return Alternative(operation_id=OperationId(op), maneuver=m, plan=None, cost=cost, risk=0.0)

    a1, a2 = alt("A", Maneuver.GO_UP, 0.1), alt("A", Maneuver.GO_DOWN, 0.5)
    b1, b2 = alt("B", Maneuver.GO_UP, 0.1), alt("B", Maneuver.KEEP_PLAN, 0.3)
    clash = {frozenset({id(a1), id(b1)})}

    def ok(x: Alternative, y: Alternative) -> bool:
        return frozenset({id(x), id(y)}) not in clash

    sel = select_joint(
        {OperationId("A"): [a1, a2], OperationId("B"): [b1, b2]},
        alpha=1,
        beta=3,
        compatible=ok,
        max_nodes=100,
    )
    assert sel is not None and sel.total == pytest.approx(0.4) and not sel.truncated
    assert sel.chosen[OperationId("A")] is a1 and sel.chosen[OperationId("B")] is b2
    tiny = select_joint(
        {OperationId("A"): [a1, a2], OperationId("B"): [b1, b2]},
        alpha=1,
        beta=3,
        compatible=ok,
        max_nodes=2,
    )
    assert tiny is None or tiny.truncated
    assert (
        select_joint(
            {OperationId("A"): [a1], OperationId("B"): [b1]},
            alpha=1,
            beta=3,
            compatible=ok,
            max_nodes=100,
        )
        is None
    )


def test_config_rejects_unknown_actions_and_kinds() -> None:
    with pytest.raises(ValueError, match="expected one of"):
        EmergencyConfig(policy={"JAMMING_ATTACK": "panic"})
    with pytest.raises(ValueError, match="unknown threat kind"):
        EmergencyConfig(policy={"ALIENS": "warn"})
    assert EmergencyConfig().beta > EmergencyConfig().alpha


def test_when_no_combination_keeps_the_tracking_tolerances_the_bare_minima_decide() -> None:
    # Head-on at a fixed altitude (no vertical room) with tolerances no lateral manoeuvre can
    # keep (600 m each, beyond the 1000 m lateral limit): rather than escalating with
    # nothing, EM searches again on the effective minima alone and recommends a plan.
    from gcs_utm.envelope import implied

    env = replace(implied(False, 10.0, 3.0), tracking_error_m=600.0)
    snap, threat = sc.scenario_los_2uas()
    ops = {
        k: replace(o, envelope=env, min_alt_amsl_m=100.0, max_alt_amsl_m=100.0)
        for k, o in snap.operations.items()
    }
    snap = replace(snap, operations=ops)
    em = make_em()
    d = em.on_threat(threat, snap)
    assert not any("no conflict-free combination" in e for e in d.escalations)
    moved = [r.selected for r in d.recommendations if r.selected is not None]
    assert moved and all(x.maneuver is not Maneuver.KEEP_PLAN for x in moved)


def test_a_conflict_between_two_unchanged_neighbours_does_not_block_the_decision() -> None:
    # A crosses B; C flies 20 m beside B (their own conflict, another threat) and is drawn
    # into A-B's problem as a neighbour. B and C may not move. Requiring B's and C's
    # unchanged plans to be compatible made every combination fail: nothing moved and A flew
    # into B. Only the threat's own pair, and every changed plan, must be conflict-free.
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)])
    b = sc.make_operation("B", [(0, -1000, 100), (0, 1000, 100)], priority=2000)
    c = sc.make_operation("C", [(20, -1000, 100), (20, 1000, 100)], priority=2000)
    snap = sc.snapshot([a, b, c])
    em = make_em()
    d = em.on_threat(sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"]), snap)
    assert not d.escalations
    (rec,) = [r for r in d.recommendations if r.operation_id == "A"]
    assert rec.selected is not None and rec.selected.plan is not None
    assert rec.selected.maneuver is not Maneuver.KEEP_PLAN
    # A's new plan is clear of both B and C
    mon = MonitoringConfig()
    from gcs_utm.core.monitoring.strategic import plan_vs_plans

    assert plan_vs_plans(rec.selected.plan, a, [b, c], sc.FRAME, mon) == []


def test_forgotten_operations_take_their_settled_recommendations_with_them() -> None:
    """A day of traffic must not accumulate in EM (``gcs-utm bench soak``): the
    recommendations of operations the airspace forgot leave memory once their threat is
    closed; while a case still refers to one it stays."""
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    recs = em.on_threat(threat, snap).recommendations
    assert recs
    ops = {r.operation_id for r in recs}
    em.forget_operations(ops)  # the threat is still open: nothing goes
    assert all(em.recommendation(r.id) is not None for r in recs)
    em.on_threat_closed(replace(threat, status=ThreatStatus.CLOSED))
    em.forget_operations({OperationId("nobody")})
    assert all(em.recommendation(r.id) is not None for r in recs)
    em.forget_operations(ops)
    assert all(em.recommendation(r.id) is None for r in recs)
    assert em.pending() == []
