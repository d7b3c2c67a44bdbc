"""Time-aware decisions (issue 30, class 2): the lead before a new plan starts comes from the
answer, upload and command times measured per vehicle; a loss predicted sooner than that
gets an immediate command (hold, climb or descend in place) chosen by priority and
geometry, proposed through the pilot prompt with an escalation that names it."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.clock import ManualClock
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager
from gcs_utm.core.emergency.immediate import choose_commands
from gcs_utm.core.emergency.lead import ResponseTimes
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
    ThreatStatus,
    Track,
    TrackId,
    VehicleKind,
)
from gcs_utm.services.emergency import EmergencyService

MON = MonitoringConfig()
A, B = OperationId("A"), OperationId("B")


def make_em(**cfg: object) -> EmergencyManager:
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    return EmergencyManager(sc.FRAME, EmergencyConfig(**cfg), td, MON)  # type: ignore[arg-type]


def test_response_times_are_the_slowest_recent_measurement_per_vehicle() -> None:
    times = ResponseTimes(EmergencyConfig(), answer_delay_s=1.5)
    assert (times.answer_s([A]), times.upload_s([A]), times.command_s([A])) == (1.5, 3.0, 1.0)
    for s in (9.0, 0.4, 0.5, 0.6, 0.7):
        times.observe("upload", A, s)
    assert times.upload_s([A]) == 9.0
    times.observe("upload", A, 0.8)  # only the last five count: the 9 s one is gone
    assert times.upload_s([A]) == 0.8
    assert times.upload_s([B]) == 3.0  # another vehicle: still the configured figure
    assert times.upload_s([A, B]) == 3.0  # a decision for both waits for the slower
    # plan start = now + answer + upload + start margin (2 s)
    assert times.plan_start([A], 100.0, 200.0) == pytest.approx(100.0 + 1.5 + 0.8 + 2.0)
    auto = ResponseTimes(EmergencyConfig(autonomous=True))
    auto.observe("answer", A, 4.0)
    assert auto.answer_s([A]) == 0.0  # nobody answers in autonomous mode
    with pytest.raises(ValueError, match="upload of A"):
        times.observe("upload", A, -1.0)
    with pytest.raises(ValueError, match="unknown figure"):
        times.observe("uplaod", A, 1.0)


def _rec(**kw: object) -> Recommendation:
    base = Recommendation(
        id=RecommendationId("t/A"),
        version=1,
        threat_id=ThreatId("t"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=A,
        created_t_s=100.0,
        deadline_t_s=120.0,
        reason="",
        state_t_s=100.0,
    )
    return replace(base, **kw)  # type: ignore[arg-type]


def test_the_service_measures_answers_and_acknowledgements_from_the_usm() -> None:
    """The USM reports every state change to the emergency service (an operator port):
    answer = accepted - proposed, command = applied - accepted, per vehicle."""
    em = make_em()
    svc = EmergencyService(em, lambda t: sc.snapshot([]), ManualClock(0.0), _nothing)
    rec = _rec(command=Command(kind=CommandKind.HOLD, operation_id=A))
    accepted = rec.transition(RecommendationState.ACCEPTED, 106.5)
    applied = accepted.transition(RecommendationState.APPLIED, 107.25)
    asyncio.run(svc.update(accepted))
    asyncio.run(svc.update(applied))
    assert em.lead.measured() == {"answer": {"A": 6.5}, "command": {"A": 0.75}}
    assert em.lead.answer_s([A]) == 6.5


async def _nothing(d: Decision) -> None:
    return None


def test_a_loss_sooner_than_the_measured_lead_gets_an_immediate_command() -> None:
    """The same threat, 10 s ahead: with the configured lead (2 + 3 + 2 s) EM proposes
    plans; once A's uploads were measured at 9 s a plan would start after the event, so EM
    proposes an immediate command instead (and says why). No margin beyond the lead here
    (``immediate_margin_s``: see the test below)."""
    snap, threat = sc.scenario_los_2uas()
    threat = replace(threat, predicted_event_at_s=snap.t_s + 10.0)
    em = make_em(immediate_margin_s=0.0)
    d = em.on_threat(threat, snap)
    assert d.recommendations and all(r.selected is not None for r in d.recommendations)
    assert not d.escalations
    em2 = make_em(immediate_margin_s=0.0)
    em2.lead.observe("upload", A, 9.0)
    d2 = em2.on_threat(threat, snap)
    assert d2.recommendations and all(r.command is not None for r in d2.recommendations)
    assert all(r.state is RecommendationState.PROPOSED for r in d2.recommendations)  # asked
    assert d2.escalations and "sooner than a new plan can start (13.0 s" in d2.escalations[0]
    (why,) = (a for a in d2.audit if a.action == "immediate")
    assert why.detail["measured_s"] == {"upload": {"A": 9.0}}


def _track(op: str, e: float, n: float, ve: float, vn: float, t_s: float) -> Track:
    la, lo = sc.FRAME.point_to_wgs84(e, n)
    return Track(
        id=TrackId(op),
        t_s=t_s,
        lat_deg=la,
        lon_deg=lo,
        alt_amsl_m=100.0,
        east_m=e,
        north_m=n,
        vel_enu_mps=(ve, vn, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=OperationId(op),
    )


def _tracked(
    b_points: list[tuple[float, float, float]],
    tb: tuple[float, float, float, float],
    priorities: tuple[int, int],
) -> AirspaceSnapshot:
    """A flies east along y = 0, 110 m before the origin; B as given; 11 s before the
    origin."""
    now = sc.T0_S + 89.0
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=priorities[0])
    b = sc.make_operation("B", b_points, priority=priorities[1])
    snap = sc.snapshot([a, b], t_s=now)
    tracks = {TrackId("A"): _track("A", -110.0, 0.0, 10.0, 0.0, now)}
    tracks[TrackId("B")] = _track("B", *tb, now)
    return replace(snap, tracks=tracks)


@pytest.mark.parametrize("priorities", [(1, 2), (3, 2)], ids=["A-lower", "B-lower"])
def test_the_lower_priority_uas_gets_the_command_that_separates(
    priorities: tuple[int, int],
) -> None:
    """Head-on, 220 m apart at 20 m/s closing: holding either one leaves the other flying
    into it, so the command is a climb (or descent) in place, and it goes to the UAS of
    lower priority; every combination tried is in the choice's record."""
    snap = _tracked([(1000, 0, 100), (-1000, 0, 100)], (110.0, 0.0, -10.0, 0.0), priorities)
    prio = dict(zip((A, B), priorities, strict=True))
    choice = choose_commands(sc_td(), snap, [A, B], snap.t_s + 3.0, snap.t_s + 6.0, prio)
    assert choice is not None and choice.clear and choice.ratio >= 1.0
    lower = min(prio, key=lambda k: prio[k])
    assert list(choice.actions) == [lower]
    assert choice.actions[lower] in {"climb", "descend"}
    (cmd,) = choice.commands.values()
    assert cmd.kind is CommandKind.GOTO and cmd.target is not None
    assert abs(cmd.target.alt_amsl_m - 100.0) >= MON.separation_vertical_m
    holds = [x for x in choice.tried if x["commands"] in ({"A": "hold"}, {"B": "hold"})]
    assert len(holds) == 2 and all(float(str(x["ratio"])) < 1.0 for x in holds)


def test_a_crossing_needs_one_command_for_the_lower_priority_uas() -> None:
    """Crossing at right angles, 110 m out each: braking or climbing the lower-priority UAS
    keeps the minima: one command, for B (priority 1)."""
    snap = _tracked([(0, -1000, 100), (0, 1000, 100)], (0.0, -110.0, 0.0, 10.0), (2, 1))
    prio = {A: 2, B: 1}
    choice = choose_commands(sc_td(), snap, [A, B], snap.t_s + 3.0, snap.t_s + 11.0, prio)
    assert choice is not None and choice.clear
    assert list(choice.actions) == [B]


def sc_td() -> TacticalDeconfliction:
    return TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)


@pytest.mark.parametrize("answered", [True, False], ids=["accepted", "still-proposed"])
def test_a_conformance_decision_does_not_undo_an_immediate_command(answered: bool) -> None:
    """A UAS told to hold is off its plan on purpose: the conformance threat that follows
    (UAS_OUT_OV, back to plan) must not send it back into the loss it avoids; nor while the
    command is still proposed (the answer may come in the same second: a plan back accepted
    right after it undid the command on a late encounter and created a loss)."""
    snap, threat = sc.scenario_los_2uas()
    threat = replace(threat, predicted_event_at_s=snap.t_s + 5.0)
    em = make_em()
    d = em.on_threat(threat, snap)
    cmds = [r for r in d.recommendations if r.command is not None]
    assert cmds, d
    for r in cmds if answered else ():
        em.on_answer(r, True, snap)
    held = cmds[0].operation_id
    out = sc.threat(ThreatKind.UAS_OUT_OV, [held], tid="t2", event_in_s=0.0)
    d2 = em.on_threat(out, snap)
    assert d2.recommendations == ()
    (why,) = d2.audit
    assert why.action == "deferred" and "t1's immediate command" in str(why.detail["reason"])
    # once the loss case is closed, conformance decides as usual again
    em.on_threat(replace(threat, status=ThreatStatus.CLOSED), snap)
    assert em.on_threat(replace(out, id=ThreatId("t3")), snap).audit[0].action != "deferred"


def test_a_fixed_wing_hold_takes_the_room_it_can_reach_not_its_whole_circle_at_once() -> None:
    """A fixed wing (22 m/s) 230 m behind a multirotor (8 m/s) on the same track, closing at
    14 m/s: told to circle where it is, it is anywhere within two turn radii (160 m) of
    where the command reached it, but no farther than its top speed carries it by then. The
    multirotor flies on and away; the circle never comes within the minima, so holding the
    fixed wing is clear. Counting the whole 160 m from the command's first instant made
    every fixed-wing command look 42 m from a loss (ratio 0.65) and nothing clear."""
    now = sc.T0_S + 89.0
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], speed_mps=8.0, ov_m=15.0)
    b = sc.make_operation("B", [(-1000, 0, 100), (1000, 0, 100)], speed_mps=22.0, ov_m=25.0)
    b = replace(b, vehicle_kind=VehicleKind.FIXED_WING, max_climb_rate_mps=5.0)
    tracks = {
        TrackId("A"): _track("A", 0.0, 0.0, 8.0, 0.0, now),
        TrackId("B"): _track("B", -230.0, 0.0, 22.0, 0.0, now),
    }
    snap = replace(sc.snapshot([a, b], t_s=now), tracks=tracks)
    choice = choose_commands(sc_td(), snap, [A, B], now + 2.0, now + 11.8, {A: 5, B: 1})
    assert choice is not None and choice.clear, choice
    assert choice.actions == {B: "hold"}
    assert 1.0 <= choice.ratio < 1.6  # the circle's 160 m still counts once it is reached


def _crossing(d_m: float) -> AirspaceSnapshot:
    """A (priority 2) east and B (priority 1) north at 10 m/s, each ``d_m`` before the
    crossing, plans timed where the tracks are."""
    now = sc.T0_S + 89.0
    t0 = now - (1000.0 - d_m) / 10.0
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=2, t0_s=t0)
    b = sc.make_operation("B", [(0, -1000, 100), (0, 1000, 100)], priority=1, t0_s=t0)
    tracks = {
        TrackId("A"): _track("A", -d_m, 0.0, 10.0, 0.0, now),
        TrackId("B"): _track("B", 0.0, -d_m, 0.0, 10.0, now),
    }
    return replace(sc.snapshot([a, b], t_s=now), tracks=tracks)


@pytest.mark.parametrize(("event_in_s", "immediate"), [(11.0, True), (13.0, False)])
def test_a_loss_just_beyond_the_lead_gets_the_immediate_command_when_it_keeps_the_minima(
    event_in_s: float, immediate: bool
) -> None:
    """A plan decided 11 s before the event starts 7 s later (answer 2 + upload 3 + margin
    2), 4 s before it: a re-route that starts that late was flown inside the minima. Within
    the lead plus ``immediate_margin_s`` (5 s) EM proposes the immediate command (B, the
    lower priority, holds) since it keeps the minima; 13 s ahead, and with no margin, the
    plans stand as before."""
    snap = _crossing(200.0)
    threat = sc.threat(
        ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=event_in_s
    )
    d = make_em().on_threat(threat, snap)
    (rec,) = d.recommendations
    assert rec.operation_id == B
    if immediate:
        assert rec.command is not None and rec.command.kind is CommandKind.HOLD
        assert d.escalations and "within a new plan's lead (7.0 s) plus 5.0 s" in d.escalations[0]
    else:
        assert rec.command is None and rec.selected is not None and not d.escalations
    plans = make_em(immediate_margin_s=0.0).on_threat(threat, snap)
    assert all(r.selected is not None for r in plans.recommendations) and not plans.escalations


@pytest.mark.parametrize(
    ("north_m", "radius_m"), [(-62.0, 5.0), (-45.0, 6.0)], ids=["inside", "within-its-volume"]
)
def test_the_command_keeps_its_uas_out_of_geofences_when_another_keeps_the_minima(
    north_m: float, radius_m: float
) -> None:
    """The crossing above: B (priority 1) would stop 60 m before the crossing, inside a no-fly
    zone of 5 m there, or 9 m from one (less than its 10 m operational volume: TD keeps its
    plans that far from fences); A's command keeps the minima too and enters nothing, so it
    is A's (the combinations that enter the fence say so in the audit)."""
    snap = _tracked([(0, -1000, 100), (0, 1000, 100)], (0.0, -110.0, 0.0, 10.0), (2, 1))
    snap = replace(snap, geofences=(sc.cylinder("G1", 0.0, north_m, radius_m),))
    prio = {A: 2, B: 1}
    choice = choose_commands(sc_td(), snap, [A, B], snap.t_s + 3.0, snap.t_s + 11.0, prio)
    assert choice is not None and choice.clear
    assert list(choice.actions) == [A]
    held = {"commands": {"B": "hold"}, "ratio": 1.0, "geofences": ["G1"]}
    if north_m < -50.0:  # in the fence itself, not only within B's volume of it
        held["intrusion"] = True
    assert held in choice.tried


def test_forgotten_operations_take_their_response_times_with_them() -> None:
    """A day of traffic must not accumulate in the response-time book (``gcs-utm bench
    soak`` grew by one deque per operation): operations the airspace forgot leave it, with
    an accepted version that was never applied; the others' figures stay."""
    em = make_em()
    em.lead.observe("upload", A, 4.0)
    em.lead.observe("answer", B, 3.0)
    accepted = _rec().transition(RecommendationState.ACCEPTED, 103.0)
    em.lead.on_state(accepted)
    em.forget_operations({A})
    assert em.lead.measured() == {"answer": {"B": 3.0}}
    assert em.lead.upload_s([A]) == EmergencyConfig().upload_time_s
    # A's acceptance went too: applying it later measures from creation, not acceptance
    em.lead.on_state(accepted.transition(RecommendationState.APPLIED, 104.0))
    assert em.lead.measured()["upload"] == {"A": 4.0}
