"""An accepted plan is checked again, against the airspace as it is, before it is uploaded.

EM verified the plan when it proposed it; the pilot answers seconds later (or much later,
up to the deadline), and in between a UAS may have appeared in flight, another plan may
have been accepted, or the vehicles may have drifted from their plans. A plan uploaded
blind then flies into a loss it was meant to avoid, or creates one. So the USM asks
:func:`plan_problem` right before the upload; a problem fails the recommendation, and EM
decides the case again on the current snapshot (``on_outcome``: one new decision, which is
the immediate command when the event is near, see :mod:`.immediate`).

The check is Monitoring's plan-against-plans check (``TacticalDeconfliction.verify``) of
the plan, as the vehicle will fly it from now on (an airborne UAS hovers after its end), at
the pair's **bare** effective minima (a decision that found nothing better than the bare
minima is not refused for the tracking tolerance it could not keep), against every other
UAS in the snapshot: its plan re-timed from its vehicle's progress (the snapshot EM decides
on), or the plan another recommendation has proposed, accepted or applied for it since.
Pure.
"""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Operation,
    OperationId,
    Recommendation,
    RecommendationState,
)

_LIVE = (RecommendationState.PROPOSED, RecommendationState.ACCEPTED, RecommendationState.APPLIED)


def _intended(em: EmContext, rec: Recommendation) -> dict[OperationId, FlightPlan]:
    """The newest plan each other UAS has been recommended (proposed, accepted or applied)."""
    latest: dict[OperationId, tuple[float, FlightPlan]] = {}
    cases = [c for c in map(em.case, em.open_threats()) if c is not None]
    for rid in {r for c in cases for r in c.rec_ids}:
        r = em.recommendation(rid)
        if r is None or r.operation_id == rec.operation_id or r.state not in _LIVE:
            continue
        if r.selected is None or r.selected.plan is None:
            continue
        prev = latest.get(r.operation_id)
        if prev is None or r.created_t_s >= prev[0]:
            latest[r.operation_id] = (r.created_t_s, r.selected.plan)
    return {k: plan for k, (_, plan) in latest.items()}


def _others(em: EmContext, rec: Recommendation, snapshot: AirspaceSnapshot) -> list[Operation]:
    intended = _intended(em, rec)
    out = []
    for k, op in snapshot.operations.items():
        if k == rec.operation_id:
            continue
        plan = intended.get(k)
        newer = plan is not None and op.plan.created_t_s < plan.created_t_s
        out.append(replace(op, plan=replace(plan, operation_id=k)) if newer and plan else op)
    return out


def plan_problem(em: EmContext, rec: Recommendation, snapshot: AirspaceSnapshot) -> str:
    """Why the accepted plan of ``rec`` must not be uploaded now ("" when it may; also for a
    command, or a UAS the snapshot does not hold): the losses of separation Monitoring finds
    on it against the other UAS as they are (see the module docstring)."""
    plan = rec.selected.plan if rec.selected is not None else None
    op = snapshot.operations.get(rec.operation_id)
    if plan is None or op is None:
        return ""
    plan = replace(plan, operation_id=op.id)
    others = _others(em, rec, snapshot)
    flags = [f for f in em.td.verify(plan, op, others, (), buffered=False) if f]
    if not flags:
        return ""
    return f"{rec.id} v{rec.version} re-checked before its upload: " + "; ".join(flags[:3])
