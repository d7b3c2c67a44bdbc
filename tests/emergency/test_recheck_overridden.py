"""A plan is not uploaded over a command decided for the same UAS since (or in the same cycle)
by another case (issue 30, a loss created by an accepted plan: enc_3_0475, a conformance
case's way back to the plan and a loss case's turn away were both decided at 144 s for the
fixed wing UAS2 and accepted together; the plan, uploaded after the command, turned the
aircraft round on its radius into UAS3: 23.9 m / 19.1 m against 50 / 40 m)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from gcs_utm.core.emergency.recheck import plan_problem
from gcs_utm.model import (
    Command,
    CommandKind,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import _crossing, make_em, sc
from test_recheck_held import _Em


def test_a_plan_is_not_uploaded_over_a_newer_command_of_another_case() -> None:
    snap = _crossing(400.0)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=35.0)
    em = make_em()
    (rec,) = em.on_threat(threat, snap).recommendations
    assert rec.selected is not None and rec.selected.plan is not None
    assert plan_problem(em.ctx, rec, snap) == ""
    uas = rec.operation_id
    turn = Recommendation(
        id=RecommendationId(f"t2/{uas}"),
        version=1,
        threat_id=ThreatId("t2"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=uas,
        created_t_s=rec.created_t_s,  # decided in the same cycle, after the plan
        deadline_t_s=rec.created_t_s + 20.0,
        command=Command(kind=CommandKind.HOLD, operation_id=uas),
        state=RecommendationState.ACCEPTED,
    )
    problem = plan_problem(_Em(em, turn), rec, snap)  # type: ignore[arg-type]
    assert f"overtaken by the command of t2/{uas}" in problem, problem
    # a command decided before the plan: the plan was decided with it in force
    older = replace(turn, created_t_s=rec.created_t_s - 1.0)
    assert plan_problem(_Em(em, older), rec, snap) == ""  # type: ignore[arg-type]
    # a command that is over, or one for another UAS, leaves the plan alone
    over = replace(turn, state=RecommendationState.REJECTED)
    assert plan_problem(_Em(em, over), rec, snap) == ""  # type: ignore[arg-type]
    other = OperationId("B" if uas == "A" else "A")
    elsewhere = replace(
        turn,
        id=RecommendationId(f"t2/{other}"),
        operation_id=other,
        command=Command(kind=CommandKind.HOLD, operation_id=other),
    )
    assert "overtaken" not in plan_problem(_Em(em, elsewhere), rec, snap)  # type: ignore[arg-type]


def test_a_plan_refused_for_a_newer_command_is_neither_replanned_nor_held() -> None:
    """enc_5_0132_fence_overtaking: the conformance case's way back for UAS2 was refused for
    a loss case's turn decided in the same cycle; the case then re-planned, found nothing and
    proposed its safe command, a hold, sent over the turn: the held fixed wing passed UAS6 at
    41.3 m / 33.0 m against 50 / 40 m. The newer command stands; the case waits its retry."""
    snap = _crossing(400.0)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=35.0)
    em = make_em()
    (rec,) = em.on_threat(threat, snap).recommendations
    uas = str(rec.operation_id)
    # another case decides a command for the same UAS in the same cycle (a hold here)
    other = sc.threat(ThreatKind.JAMMING_ATTACK, [uas], tid="t2", t_s=snap.t_s, event_in_s=0.0)
    (cmd,) = em.on_threat(other, snap).recommendations
    assert cmd.command is not None and cmd.operation_id == rec.operation_id
    for r in (rec, cmd):
        em.on_answer(r, True, snap)
    problem = em.plan_problem(em.ctx.recommendation(rec.id), snap)  # type: ignore[arg-type]
    assert "overtaken by the command of t2/" in problem, problem
    d = em.on_outcome(rec.id, rec.version, False, f"not uploaded: {problem}", snap)
    assert [(r.id, r.state) for r in d.recommendations] == [(rec.id, RecommendationState.FAILED)]
    assert not d.escalations
    assert any(a.action == "overtaken" for a in d.audit), [a.action for a in d.audit]
    # decided again once the retry is due, with the command in force
    assert not em.supervise(replace(snap, t_s=snap.t_s + 1.0)).recommendations
    later = em.supervise(replace(snap, t_s=snap.t_s + em.config.retry_after_s))
    assert any(r.id == rec.id and r.version > rec.version for r in later.recommendations)
