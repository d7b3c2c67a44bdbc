"""The re-check before an upload takes a UAS told to hold where it stops, not on its plan
(issue 30, a loss created by an accepted plan: enc_3_0219, EM held UAS2 and, in the same
cycle, gave UAS5 a plan verified against UAS2's plan moving on; UAS5 flew past the held
UAS2 at 47.5 m / 17 m)."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.emergency.held import circling_elsewhere, held_plan
from gcs_utm.core.emergency.recheck import plan_problem
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
    TrackId,
    VehicleKind,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import _crossing, _track, make_em, sc


@dataclass
class _Case:
    rec_ids: list[RecommendationId] = field(default_factory=list)


class _Em:
    """The EM context with one more open case: C told to hold."""

    def __init__(self, em: object, hold: Recommendation) -> None:
        self._em, self._hold = em, hold
        self.td = em.ctx.td  # type: ignore[attr-defined]

    def open_threats(self) -> list[ThreatId]:
        return [*self._em.ctx.open_threats(), self._hold.threat_id]  # type: ignore[attr-defined]

    def case(self, tid: ThreatId) -> _Case | None:
        if tid == self._hold.threat_id:
            return _Case([self._hold.id])
        return self._em.ctx.case(tid)  # type: ignore[attr-defined,no-any-return]

    def recommendation(self, rid: RecommendationId) -> Recommendation | None:
        if rid == self._hold.id:
            return self._hold
        return self._em.ctx.recommendation(rid)  # type: ignore[attr-defined,no-any-return]


def test_a_plan_past_where_a_held_uas_stops_is_not_uploaded() -> None:
    snap = _crossing(400.0)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=35.0)
    em = make_em()
    (rec,) = em.on_threat(threat, snap).recommendations
    assert rec.selected is not None and rec.selected.plan is not None
    # C stands (speed 0) on B's new path, where B passes 30 s from now; C's plan leaves at
    # once, north at 10 m/s: 300 m away by then
    lp = plan_to_local(rec.selected.plan, sc.FRAME)
    e, n, z = (float(c[0]) for c in lp.coords(np.array([snap.t_s + 30.0])))
    c = sc.make_operation("C", [(e, n, z), (e, n + 1500.0, z)], priority=3, t0_s=snap.t_s)
    track = replace(_track("C", e, n, 0.0, 0.0, snap.t_s), alt_amsl_m=z)
    with_c = replace(
        snap,
        operations={**snap.operations, c.id: c},
        tracks={**snap.tracks, TrackId("C"): track},
    )
    assert plan_problem(em.ctx, rec, with_c) == ""  # C's plan is long gone by then
    hold = Recommendation(
        id=RecommendationId("tC/C"),
        version=1,
        threat_id=ThreatId("tC"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OperationId("C"),
        created_t_s=snap.t_s,
        deadline_t_s=snap.t_s + 20.0,
        command=Command(kind=CommandKind.HOLD, operation_id=OperationId("C")),
        state=RecommendationState.ACCEPTED,
    )
    problem = plan_problem(_Em(em, hold), rec, with_c)  # type: ignore[arg-type]
    assert "separation with C" in problem, problem
    # a hold that is over (rejected) leaves C on its plan
    over = replace(hold, state=RecommendationState.REJECTED)
    assert plan_problem(_Em(em, over), rec, with_c) == ""  # type: ignore[arg-type]


def test_the_re_check_takes_the_other_uas_as_tds_traffic() -> None:
    """A UAS on the ground is not traffic for TD, whatever its plan says; the re-check took
    every operation's plan as it was (and so a fixed wing seen on its loiter circle at its
    plan's end, enc_1_0180), refusing plans TD had verified against the traffic."""
    snap = _crossing(400.0)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=35.0)
    em = make_em()
    (rec,) = em.on_threat(threat, snap).recommendations
    assert rec.selected is not None and rec.selected.plan is not None
    lp = plan_to_local(rec.selected.plan, sc.FRAME)
    e, n, z = (float(c[0]) for c in lp.coords(np.array([snap.t_s + 30.0])))
    g = sc.make_operation("G", [(e - 300.0, n, z), (e + 300.0, n, z)], t0_s=snap.t_s)
    with_g = replace(snap, operations={**snap.operations, g.id: g})
    assert "separation with G" in plan_problem(em.ctx, rec, with_g)
    on_ground = replace(with_g, grounded=frozenset({g.id}))
    assert plan_problem(em.ctx, rec, on_ground) == ""


def test_a_fixed_wing_after_its_plan_away_from_its_end_circles_where_it_is() -> None:
    """A fixed wing held (or sent on) by a command after its plan ended circles where it is;
    TD's traffic takes it at its last waypoint (enc_2_0107: a plan verified that way ended
    beside the held aircraft's circle, flown at 2.7 m). Near its end point it is on its end
    circle (TD's loiter), and a multirotor hovers."""
    snap = _crossing(400.0)
    f = sc.make_operation("F", [(-600.0, 0.0, 100.0), (0.0, 0.0, 100.0)], t0_s=snap.t_s - 80.0)
    f = replace(f, vehicle_kind=VehicleKind.FIXED_WING)
    assert f.plan.end_t_s < snap.t_s

    def at(e: float, op: Operation) -> AirspaceSnapshot:
        track = replace(_track("F", e, 0.0, 0.0, 20.0, snap.t_s), operation_id=op.id)
        return replace(
            snap,
            operations={**snap.operations, op.id: op},
            tracks={**snap.tracks, TrackId("F"): track},
            airborne=frozenset({op.id}),
        )

    assert circling_elsewhere(f, at(500.0, f), sc.FRAME)
    assert not circling_elsewhere(f, at(50.0, f), sc.FRAME)
    multirotor = replace(f, vehicle_kind=VehicleKind.MULTIROTOR)
    assert not circling_elsewhere(multirotor, at(500.0, multirotor), sc.FRAME)
    held = held_plan(f, at(500.0, f), sc.FRAME, snap.t_s + 300.0)
    assert held is not None
    here = plan_to_local(held, sc.FRAME).position_at(snap.t_s + 100.0)
    assert abs(float(here[0]) - 500.0) < 1.0 and abs(float(here[1])) < 1.0
