"""Resolutions that can be flown (issue 19 item 3, issue 26 item 7): plans start where the
UAS will be when it gets them, stay inside each vehicle's performance envelope, never go
below the safety floor, and a fixed wing is never asked to hold in place."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.envelope import PerformanceEnvelope
from gcs_utm.model import (
    Alternative,
    Maneuver,
    Operation,
    OperationId,
    ThreatKind,
    VehicleKind,
    default_envelope,
)

MON = MonitoringConfig()


def make_td(**cfg: object) -> TacticalDeconfliction:
    return TacticalDeconfliction(sc.FRAME, DeconflictionConfig(**cfg), MON)  # type: ignore[arg-type]


def moved(alts: dict[OperationId, list[Alternative]]) -> list[Alternative]:
    return [a for v in alts.values() for a in v if a.maneuver is not Maneuver.KEEP_PLAN]


def rates(alt: Alternative) -> tuple[float, float, float]:
    """Largest horizontal speed, climb and descent (m/s) over segments of at least 0.5 s."""
    assert alt.plan is not None
    lp = plan_to_local(alt.plan, sc.FRAME)
    dt = np.diff(lp.t)
    keep = dt >= 0.5
    vh = np.hypot(np.diff(lp.e), np.diff(lp.n))[keep] / dt[keep]
    vz = np.diff(lp.z)[keep] / dt[keep]
    return float(vh.max()), float(max(vz.max(), 0.0)), float(max(-vz.min(), 0.0))


def test_envelope_defaults_follow_the_vehicle_kind() -> None:
    mr = default_envelope(VehicleKind.MULTIROTOR, 8.0, 3.0)
    assert (mr.climb_rate_mps, mr.descent_rate_mps, mr.can_hover) == (3.0, 1.5, True)
    fw = default_envelope(VehicleKind.FIXED_WING, 20.0, 5.0)
    assert fw.descent_rate_mps == 3.0 and not fw.can_hover
    assert fw.min_speed_mps == pytest.approx(14.0) and fw.turn_radius_m > 0.0


def test_every_new_plan_descends_and_climbs_within_the_envelope() -> None:
    """Head-on multirotors: go down, go up and the joint deformations ask at most the
    descent rate (1.5 m/s) and the climb rate (3 m/s); TD used to time descents with the
    climb rate times 1.2 (3.6 m/s)."""
    snap, threat = sc.scenario_los_2uas()
    td = make_td()
    alts = td.resolve_loss_of_separation(threat, snap)
    downs = [a for a in moved(alts) if a.maneuver is Maneuver.GO_DOWN]
    assert downs
    for a in moved(alts):
        env = snap.operations[a.operation_id].performance()
        vh, up, down = rates(a)
        assert down <= env.descent_rate_mps * 1.001, (a.maneuver, down)
        assert up <= env.climb_rate_mps * 1.001, (a.maneuver, up)
        assert vh <= env.max_speed_mps * 1.001, (a.maneuver, vh)


def test_an_injected_envelope_is_the_one_used() -> None:
    snap, threat = sc.scenario_los_2uas()
    slow = PerformanceEnvelope(
        climb_rate_mps=1.0,
        descent_rate_mps=0.5,
        min_speed_mps=0.0,
        max_speed_mps=12.0,
        turn_radius_m=0.0,
        can_hover=True,
    )
    ops = {k: replace(o, envelope=slow) for k, o in snap.operations.items()}
    alts = make_td().resolve_loss_of_separation(threat, replace(snap, operations=ops))
    for a in moved(alts):
        _, up, down = rates(a)
        assert up <= 1.001 and down <= 0.5005, (a.maneuver, up, down)


def crossing(kind_a: VehicleKind) -> tuple[Operation, Operation]:
    """A flies east, B north; they meet at the origin at the same time (60 s ahead)."""
    speed = 20.0 if kind_a is VehicleKind.FIXED_WING else 10.0
    a = sc.make_operation("A", [(-60 * speed, 0, 100), (1500, 0, 100)], speed_mps=speed)
    a = replace(a, vehicle_kind=kind_a, cruise_speed_mps=speed)
    b = sc.make_operation("B", [(0, -600, 100), (0, 1500, 100)], priority=5)
    return a, b


def test_a_fixed_wing_never_gets_a_hold_in_place() -> None:
    for kind, expect_delay in ((VehicleKind.MULTIROTOR, True), (VehicleKind.FIXED_WING, False)):
        a, b = crossing(kind)
        snap = sc.snapshot([a, b])
        threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], event_in_s=60)
        alts = make_td().resolve_loss_of_separation(threat, snap)
        got = {x.maneuver for x in alts[OperationId("A")]}
        assert (Maneuver.DELAY in got) is expect_delay, (kind, got)
        if kind is VehicleKind.FIXED_WING:
            env = a.performance()
            for x in alts[OperationId("A")]:
                if x.maneuver is Maneuver.KEEP_PLAN:
                    continue
                assert x.plan is not None
                lp = plan_to_local(x.plan, sc.FRAME)
                dt = np.diff(lp.t)
                v3 = np.sqrt(np.diff(lp.e) ** 2 + np.diff(lp.n) ** 2 + np.diff(lp.z) ** 2)
                assert float((v3[dt >= 0.5] / dt[dt >= 0.5]).min()) >= env.min_speed_mps * 0.98


def test_no_generated_waypoint_below_the_safety_floor() -> None:
    """Head-on at 20 m above home: going down would need about 40 m; the floor (home + 10 m)
    stops the cords there, so no plan goes below it (issue 26: a copter was sent to 5 m)."""
    home = (0.0, 0.0, 0.0)
    a = sc.make_operation("A", [(-1000, 0, 20), (1000, 0, 20)], home_enz=home)
    b = sc.make_operation("B", [(1000, 0, 20), (-1000, 0, 20)], priority=2, home_enz=home)
    snap = sc.snapshot([a, b])
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], event_in_s=100)
    td = make_td()
    alts = td.resolve_loss_of_separation(threat, snap)
    assert moved(alts)
    for x in moved(alts):
        assert x.plan is not None
        low = min(w.alt_amsl_m for w in x.plan.waypoints)
        assert low >= 10.0 - 1e-6, (x.maneuver, low)
    # The configured floor moves with the key.
    td30 = make_td(min_height_above_home_m=30.0)
    for x in moved(td30.resolve_loss_of_separation(threat, snap)):
        assert x.plan is not None
        assert min(w.alt_amsl_m for w in x.plan.waypoints[1:]) >= 30.0 - 1e-6


def test_floor_drops_a_single_uas_route_below_home_but_lets_it_land() -> None:
    """Return home descends to home (a touchdown, allowed). A reroute around a geofence
    whose new corner points would lie below the floor (home 95 m, floor 105 m, plan at
    100 m) is dropped with the reason; the filed waypoints themselves are not judged."""
    op = sc.make_operation(
        "A", [(0, 0, 100), (3000, 0, 100)], home_enz=(-200, 0, 0), endurance_s=3000.0
    )
    t = sc.T0_S + 10
    threat = sc.threat(ThreatKind.LACK_OF_BATTERY, ["A"], t_s=t)
    td = make_td()
    (home,) = td.resolve_single(threat, op.id, sc.snapshot([op], t_s=t), {Maneuver.RETURN_HOME})
    assert home.plan is not None and home.plan.waypoints[-1].alt_amsl_m == pytest.approx(0.0)
    fence = sc.cylinder("f", 1500.0, 0.0, 100.0)
    conflict = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["A"], t_s=t, geofence_id=fence.id)
    snap = sc.snapshot([op], [fence], t_s=t)
    (ok,) = td.resolve_single(conflict, op.id, snap, {Maneuver.REROUTE})
    assert ok.plan is not None and len(ok.plan.waypoints) > 2
    assert op.home is not None
    low = replace(op, home=replace(op.home, alt_amsl_m=95.0))
    snap_low = sc.snapshot([low], [fence], t_s=t)
    assert td.resolve_single(conflict, op.id, snap_low, {Maneuver.REROUTE}) == []
    assert any("safety floor" in d.reason for d in td.dropped)


@pytest.mark.parametrize("kind", [VehicleKind.MULTIROTOR, VehicleKind.FIXED_WING])
def test_new_plans_start_where_the_uas_will_be_when_it_gets_them(kind: VehicleKind) -> None:
    """Decision at T0; the plan is answered, uploaded and started 25 s later: its first
    waypoint is the UAS's position on its plan then (ahead of it on its path, never a point
    it has already passed), and its times start there."""
    a, b = crossing(kind)
    snap = sc.snapshot([a, b])
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], event_in_s=60)
    start = sc.T0_S + 25.0
    alts = make_td().resolve_loss_of_separation(threat, snap, start_t_s=start)
    mine = [x for x in alts[OperationId("A")] if x.maneuver is not Maneuver.KEEP_PLAN]
    assert mine
    lp_a = plan_to_local(a.plan, sc.FRAME)
    at_receipt = lp_a.position_at(sc.T0_S + 23.0)  # answered at +20 s, uploaded by +23 s
    for x in mine:
        assert x.plan is not None
        first = x.plan.waypoints[0]
        assert first.t_s == pytest.approx(start)
        e, n = sc.FRAME.point_to_local(first.lat_deg, first.lon_deg)
        assert np.allclose([e, n, first.alt_amsl_m], lp_a.position_at(start), atol=0.01)
        assert e > at_receipt[0]  # ahead along its eastbound path
    # Without a start time the plan starts at the decision, behind the UAS by then.
    now = make_td().resolve_loss_of_separation(threat, snap)
    assert all(
        x.plan is not None and x.plan.waypoints[0].t_s == pytest.approx(sc.T0_S)
        for x in now[OperationId("A")]
        if x.maneuver is not Maneuver.KEEP_PLAN
    )


def test_a_new_plan_carries_timed_points_of_the_path_before_it_starts() -> None:
    """The vehicle may get the plan as early as 3 s after the decision (an immediate answer
    plus the upload) and flies to the first waypoint still ahead, untimed: the plan carries
    its current path every 5 s from then to the start, so that leg is at most 5 s and every
    later leg keeps its time (a delay plan held at its start point 17 s early without)."""
    a, b = crossing(VehicleKind.MULTIROTOR)
    snap = sc.snapshot([a, b])
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], event_in_s=60)
    start = sc.T0_S + 25.0
    alts = make_td().resolve_loss_of_separation(
        threat, snap, start_t_s=start, lead_in_from_t_s=sc.T0_S + 3.0
    )
    lp_a = plan_to_local(a.plan, sc.FRAME)
    mine = moved({OperationId("A"): alts[OperationId("A")]})
    assert mine
    for x in mine:
        assert x.plan is not None
        lead = [w for w in x.plan.waypoints if w.t_s < start - 1e-6]
        # from the receipt itself (see test_lead_times), then every 5 s back from the start
        assert [w.t_s - sc.T0_S for w in lead] == pytest.approx([3.0, 5.0, 10.0, 15.0, 20.0])
        for w in lead:
            e, n = sc.FRAME.point_to_local(w.lat_deg, w.lon_deg)
            assert np.allclose([e, n, w.alt_amsl_m], lp_a.position_at(w.t_s), atol=0.01)


def test_lead_in_never_goes_past_a_plan_that_is_over() -> None:
    """A UAS past its last waypoint (hovering there) gets no lead-in after it."""
    a, b = crossing(VehicleKind.MULTIROTOR)
    late = sc.T0_S + 400.0
    snap = sc.snapshot([a, b], t_s=late)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=late, event_in_s=60)
    alts = make_td().resolve_loss_of_separation(
        threat, snap, start_t_s=late + 25.0, lead_in_from_t_s=late + 3.0
    )
    for x in moved(alts):
        assert x.plan is not None  # the plan's times never go backwards (FlightPlan checks)


@pytest.mark.parametrize(
    ("field", "value"),
    [("descent_rate_mps", 0.0), ("min_speed_mps", 50.0), ("turn_radius_m", float("nan"))],
)
def test_an_envelope_that_cannot_be_flown_is_refused_naming_the_field(
    field: str, value: float
) -> None:
    from gcs_utm.envelope import EnvelopeError

    good = default_envelope(VehicleKind.FIXED_WING, 20.0, 5.0)
    with pytest.raises(EnvelopeError) as info:
        replace(good, **{field: value})
    assert info.value.field_name == field


def test_a_fixed_wing_turn_must_fit_its_turn_radius() -> None:
    from gcs_utm.core.deconfliction.geometry import LocalPlan
    from gcs_utm.core.deconfliction.safety import turn_flags

    def lp(pts: list[tuple[float, float]]) -> LocalPlan:
        arr = np.array(pts, dtype=np.float64)
        k = arr.shape[0]
        return LocalPlan(arr[:, 0], arr[:, 1], np.full(k, 100.0), np.arange(k) * 10.0)

    old = lp([(0.0, 0.0), (1000.0, 0.0)])
    back = lp([(0.0, 0.0), (200.0, 0.0), (0.0, 1.0)])  # turn back at a generated point
    assert turn_flags(back, old, 80.0) and "turn radius" in turn_flags(back, old, 80.0)[0]
    gentle = lp([(0.0, 0.0), (200.0, 0.0), (400.0, 115.0)])  # 30 deg: 21 m each side
    assert turn_flags(gentle, old, 80.0) == []
    tight = lp([(0.0, 0.0), (200.0, 0.0), (200.0, 60.0)])  # 90 deg, 60 m leg < 80 m
    assert turn_flags(tight, old, 80.0)
    assert turn_flags(tight, tight, 80.0) == []  # the filed plan's own corners are not judged
    assert turn_flags(back, old, 0.0) == []  # a multirotor turns on the spot


def test_a_fixed_wing_keeps_the_filed_plans_turns_at_a_new_height() -> None:
    """A go_up raises the pilot's corners: the turn is the filed plan's (the vehicle flies it
    as it flies that plan), whatever the short legs the deformation puts around it. A PX4
    plane's 153 deg turn towards its approach dropped every avoidance of an intruder."""
    from gcs_utm.core.deconfliction.geometry import LocalPlan
    from gcs_utm.core.deconfliction.safety import turn_flags

    def lp(pts: list[tuple[float, float, float]]) -> LocalPlan:
        arr = np.array(pts, dtype=np.float64)
        k = arr.shape[0]
        return LocalPlan(arr[:, 0], arr[:, 1], arr[:, 2], np.arange(k) * 10.0)

    # north 1700 m, then back south-west to the approach: a 153 deg turn
    old = lp([(0.0, 0.0, 40.0), (0.0, 1700.0, 40.0), (-400.0, 900.0, 30.0)])
    up = lp(
        [(0.0, 0.0, 40.0), (0.0, 1600.0, 90.0), (0.0, 1700.0, 90.0), (-40.0, 1620.0, 90.0),
         (-400.0, 900.0, 30.0)]
    )  # fmt: skip
    assert turn_flags(up, old, 80.0) == []
    # moved sideways, the corner is generated: judged
    left = lp(
        [(0.0, 0.0, 40.0), (0.0, 1600.0, 40.0), (30.0, 1700.0, 40.0), (-40.0, 1620.0, 40.0),
         (-400.0, 900.0, 30.0)]
    )  # fmt: skip
    assert turn_flags(left, old, 80.0)
    # sharper than the filed turn at the same place: judged
    sharper = lp([(0.0, 0.0, 40.0), (0.0, 1700.0, 90.0), (-20.0, 1000.0, 90.0)])
    assert turn_flags(sharper, old, 80.0)


def test_the_lead_in_is_verified_against_geofences_too() -> None:
    """The vehicle flies the lead-in (its current path) until the plan starts: a fence on that
    stretch makes the plan unsafe even when the manoeuvre after it is clear."""
    op = sc.make_operation("A", [(0, 0, 100), (3000, 0, 100)])
    fence = sc.cylinder("f", 100.0, 0.0, 50.0)
    snap = sc.snapshot([op], [fence])
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["A"], geofence_id=fence.id)
    td = make_td()
    kw = {"maneuvers": {Maneuver.DIRECT_TO_GOAL}, "start_t_s": sc.T0_S + 25.0}
    clear = td.resolve_single(threat, op.id, snap, **kw)  # type: ignore[arg-type]
    assert [a.maneuver for a in clear] == [Maneuver.DIRECT_TO_GOAL]
    led = td.resolve_single(threat, op.id, snap, lead_in_from_t_s=sc.T0_S + 3.0, **kw)  # type: ignore[arg-type]
    assert led == [] and any("geofence f" in d.reason for d in td.dropped)
