"""A UAS whose plan failed twice for a loss of separation is proposed EM's immediate command,
chosen against all traffic, not a bare hold (``core/emergency/failed_safe.py``).

``enc_8_0233_late_vertical``: the way round UAS5 of the multirotor UAS2 was refused twice
before its upload; the hold then proposed stopped it 25 m beside the path of the fixed wing
UAS6, 33 m above it, and UAS6 passed it at 41.3 m / 33.1 m against 50 / 40 m."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.emergency.failed_safe import after_failure
from gcs_utm.core.emergency.immediate import commands_now
from gcs_utm.model import CommandKind, RecommendationState, Threat, ThreatId, ThreatKind

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import A, B, make_em, sc
from test_immediate_third_party import NOW, _overtaking


def _case(kind: ThreatKind) -> Case:
    threat = Threat(
        id=ThreatId("t1"),
        kind=kind,
        uas_ids=(A, B) if kind is ThreatKind.LOSS_OF_SEPARATION else (B,),
        detected_at_s=NOW,
        predicted_event_at_s=NOW + 9.0,
    )
    return Case(threat=threat, action=make_em().config.action_for(kind), attempt_t_s=NOW)


def test_a_loss_gets_the_immediate_command_checked_against_all_traffic() -> None:
    """B (overtaking A) held in place stops in the path of the fixed wing C coming up behind
    it: the bare hold loses the minima to C; the immediate command for B takes C into
    account (C is commanded too, or B does something else)."""
    snap = _overtaking()
    em = make_em()
    case = _case(ThreatKind.LOSS_OF_SEPARATION)
    choice = commands_now(em.ctx, snap, [B], case.threat.predicted_event_at_s)
    assert choice is not None and choice.commands
    bare = {B: CommandKind.HOLD}
    assert {k: c.kind for k, c in choice.commands.items()} != bare  # the case the test needs
    d = after_failure(em.ctx, case, [B], snap, "t1/B v2 for B failed")
    proposed = {
        r.operation_id: r.command.kind
        for r in d.recommendations
        if r.command is not None and r.state is RecommendationState.PROPOSED
    }
    assert proposed == {k: c.kind for k, c in choice.commands.items()}
    assert d.escalations and "immediate command" in d.escalations[0]


def test_other_threats_keep_their_safe_command() -> None:
    snap = _overtaking()
    em = make_em()
    d = after_failure(em.ctx, _case(ThreatKind.LACK_OF_BATTERY), [B], snap, "failed")
    (rec,) = d.recommendations
    assert rec.command is not None and rec.command.kind is CommandKind.LAND


def test_the_second_failure_of_a_loss_case_s_plan_proposes_the_immediate_command() -> None:
    """Through EM: a plan accepted for the loss, refused before its upload, re-planned,
    refused again: the escalation proposes the immediate command (it used to be a bare hold
    of the UAS whose plan failed, checked against nothing)."""
    snap, threat = sc.scenario_los_2uas()
    threat = replace(threat, predicted_event_at_s=snap.t_s + 300.0)
    em = make_em()
    d = em.on_threat(threat, snap)
    for attempt in range(2):
        plans = [
            r
            for r in d.recommendations
            if r.state is RecommendationState.PROPOSED and r.command is None
        ]
        assert plans, (attempt, d)
        (acc,) = em.on_answer(plans[0], True, snap).recommendations
        d = em.on_outcome(acc.id, acc.version, False, "re-checked before its upload", snap)
    assert d.escalations, d
    assert "; immediate command " in d.escalations[-1], d.escalations
