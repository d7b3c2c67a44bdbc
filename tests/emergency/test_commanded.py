"""A fixed wing under a hold or go-to command (issue 30, geofence intrusions on seed 3):
TD starts its new plans where the command takes it, not on its plan (enc_3_0409, enc_3_0235),
and a hold whose circle would enter a fence is replaced by a command that does not."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.emergency.commanded import command_in_force, commanded_snapshot
from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.emergency.fenced_hold import fence_free_hold
from gcs_utm.core.emergency.single import single
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    Maneuver,
    OperationId,
    Position,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
    TrackId,
    VehicleKind,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import _track, make_em, sc

B = OperationId("B")
SPEED_MPS = 20.0


def _plane(now: float, fences: tuple[object, ...] = ()) -> AirspaceSnapshot:
    """B, a fixed wing filed north along e = 0 (at the origin now), turned away: its track is
    200 m east of its plan, flying east at 20 m/s."""
    t0 = now - 1000.0 / SPEED_MPS
    b = sc.make_operation(
        "B", [(0, -1000, 100), (0, 1000, 100)], t0_s=t0, speed_mps=SPEED_MPS, ov_m=25.0
    )
    b = replace(b, vehicle_kind=VehicleKind.FIXED_WING, max_climb_rate_mps=5.0)
    snap = sc.snapshot([b], list(fences), t_s=now)  # type: ignore[arg-type]
    return replace(snap, tracks={TrackId("B"): _track("B", 200.0, 0.0, SPEED_MPS, 0.0, now)})


def _command(now: float, cmd: Command) -> Recommendation:
    return Recommendation(
        id=RecommendationId("t0/B"),
        version=1,
        threat_id=ThreatId("t0"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=B,
        created_t_s=now - 3.0,
        deadline_t_s=now + 10.0,
        command=cmd,
        state=RecommendationState.APPLIED,
        state_t_s=now - 1.0,
    )


def _goto(now: float) -> Command:
    la, lo = sc.FRAME.point_to_wgs84(2000.0, 0.0)
    return Command(
        kind=CommandKind.GOTO,
        operation_id=B,
        target=Position(lat_deg=la, lon_deg=lo, alt_amsl_m=100.0),
    )


def test_a_fixed_wing_under_a_goto_starts_its_new_plan_where_the_goto_takes_it() -> None:
    """The new plan of B (a geofence conflict ahead on its filed plan) starts 7 s from now
    (answer 2, upload 3, margin 2): where the go-to takes B by then, 140 m further east
    (340, 0), not where its plan will be, offset by how far B is off it now (200, 140): a
    start 200 m from the aircraft, which then turned back across the fence to reach it."""
    now = sc.T0_S + 89.0
    snap = _plane(now, (sc.cylinder("G1", 0.0, 600.0, 60.0),))
    em = make_em()
    em.ctx.recs[RecommendationId("t0/B")] = _command(now, _goto(now))
    assert command_in_force(em.ctx, snap.operations[B]) is not None
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["B"], t_s=now, event_in_s=40.0)
    case = Case(threat, Action.REROUTE, now)
    d = single(em.ctx, case, B, snap, frozenset({Maneuver.REROUTE, Maneuver.BACK_TO_PLAN}))
    plans = [r.selected.plan for r in d.recommendations if r.selected and r.selected.plan]
    assert plans, d
    start_t = em.ctx.plan_start(threat, now)
    for plan in plans:
        lp = plan_to_local(plan, sc.FRAME)
        e, n, _ = (float(c[0]) for c in lp.coords(np.array([start_t])))
        assert np.hypot(e - 340.0, n) < 15.0, (plan.waypoints, e, n)


def test_a_plan_newer_than_the_command_or_a_hovering_uas_is_not_commanded() -> None:
    now = sc.T0_S + 89.0
    snap = _plane(now)
    em = make_em()
    em.ctx.recs[RecommendationId("t0/B")] = _command(now, _goto(now))
    b = snap.operations[B]
    newer = replace(b, plan=replace(b.plan, created_t_s=now))
    assert command_in_force(em.ctx, newer) is None
    rotor = replace(b, vehicle_kind=VehicleKind.MULTIROTOR)
    snap2 = replace(snap, operations={B: rotor})
    assert commanded_snapshot(em.ctx, snap2, B, now + 7.0) is snap2
    # held: where it is now until the new plan starts, then its plan shifted by the wait
    em.ctx.recs[RecommendationId("t0/B")] = _command(
        now, Command(kind=CommandKind.HOLD, operation_id=B)
    )
    held = commanded_snapshot(em.ctx, snap, B, now + 7.0).operations[B].plan
    lp = plan_to_local(held, sc.FRAME)
    e, n, _ = lp.coords(np.array([now, now + 7.0, now + 7.0 + 10.0]))
    assert np.allclose(e[:2], 200.0, atol=0.5) and np.allclose(n[:2], 0.0, atol=0.5)
    assert abs(n[2] - n[1]) > 100.0  # then on towards its next waypoint


def test_a_fixed_wing_hold_that_circles_into_a_fence_is_replaced() -> None:
    """No alternative for B, a fixed wing flying north 120 m west of a 60 m fence's centre
    (60 m from its edge) and 200 m short of it: held there it circles up to two turn radii
    (160 m) around, into the fence. EM
    proposes a command whose room enters no fence instead (the hold is named in the audit
    as entering G1); without the fence the hold stands."""
    now = sc.T0_S + 89.0
    fence = sc.cylinder("G1", 320.0, 0.0, 60.0)
    snap = _plane(now, (fence,))
    # north, 200 m before passing the fence's side
    snap = replace(snap, tracks={TrackId("B"): _track("B", 200.0, -200.0, 0.0, SPEED_MPS, now)})
    em = make_em()
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["B"], t_s=now, event_in_s=30.0)
    instead = fence_free_hold(em.ctx, threat, B, snap)
    assert instead is not None
    cmds, actions = instead
    assert cmds[B].kind is not CommandKind.HOLD or actions[B] != "hold", actions
    d = single(em.ctx, Case(threat, Action.REROUTE, now), B, snap, frozenset())
    (rec,) = d.recommendations
    assert rec.command == cmds[B]
    clear = replace(snap, geofences=())
    assert fence_free_hold(em.ctx, threat, B, clear) is None
    d2 = single(make_em().ctx, Case(threat, Action.REROUTE, now), B, clear, frozenset())
    (rec2,) = d2.recommendations
    assert rec2.command is not None and rec2.command.kind is CommandKind.HOLD
