"""What every decision starts from and what its audit says about the options: the airspace
as other cases intend it (:func:`intended`) and the audit detail of TD's alternatives and the
selection (:func:`detail`). Pure."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.emergency.selection import Selection, weighted
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    OperationId,
    Recommendation,
    RecommendationState,
)


def intended(em: EmContext, snapshot: AirspaceSnapshot, case: Case) -> AirspaceSnapshot:
    """``snapshot`` with every plan another case has recommended and that is not in the
    airspace yet (proposed or accepted) in place of the UAS's plan: overlapping threats
    decided one after the other build on each other's plans (three pairwise threats
    among three UAS, each decided on the filed plans, gave two of them plans that met)."""
    live = (RecommendationState.PROPOSED, RecommendationState.ACCEPTED)
    latest: dict[OperationId, Recommendation] = {}
    for r in em.recs.values():
        if r.threat_id == case.threat.id or r.state not in live:
            continue
        if r.selected is None or r.selected.plan is None:
            continue
        prev = latest.get(r.operation_id)
        if prev is None or r.created_t_s >= prev.created_t_s:
            latest[r.operation_id] = r
    ops = snapshot.operations
    # An accepted plan the airspace already holds (or a newer one: uploads stamp the plan
    # they install with their time) is not replaced; the outcome may not be reported.
    changed = {
        k: replace(ops[k], plan=replace(r.selected.plan, operation_id=k))
        for k, r in latest.items()
        if k in ops
        and r.selected is not None
        and r.selected.plan is not None
        and ops[k].plan.created_t_s < r.created_t_s
    }
    if not changed:
        return snapshot
    return replace(snapshot, operations={**ops, **changed})


def _alt_record(alt: Alternative, alpha: float, beta: float) -> dict[str, object]:
    return {
        "operation_id": alt.operation_id,
        "maneuver": alt.maneuver.value,
        "cost": round(alt.cost, 6),
        "risk": round(alt.risk, 6),
        "score": round(weighted(alt, alpha, beta), 6),
        "detail": alt.detail,
        "waypoints": 0 if alt.plan is None else len(alt.plan.waypoints),
    }


def detail(
    em: EmContext,
    options: dict[OperationId, list[Alternative]],
    sel: Selection | None,
    reason: str,
) -> dict[str, object]:
    """The audit detail of a decision: every alternative with its cost, risk and score, the
    weights, the selection and what TD dropped (and why)."""
    cfg = em.config
    return {
        "reason": reason,
        "alpha": cfg.alpha,
        "beta": cfg.beta,
        "alternatives": [
            _alt_record(x, cfg.alpha, cfg.beta) for alts in options.values() for x in alts
        ],
        "selected": None if sel is None else {k: v.maneuver.value for k, v in sel.chosen.items()},
        "total": None if sel is None else round(sel.total, 6),
        "explored": None if sel is None else sel.explored,
        "truncated": None if sel is None else sel.truncated,
        "dropped": [
            {"operation_id": x.operation_id, "maneuver": x.maneuver.value, "reason": x.reason}
            for x in em.td.dropped
        ],
    }
