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
UAS of TD's traffic (``TacticalDeconfliction.others``: after its plan, a UAS hovers at its
end or flies the loiter circle it is seen on, as when the plan was made): its plan re-timed
from its vehicle's progress (the snapshot EM decides on), or the plan another recommendation
has proposed, accepted or applied for it since, or, when that newest recommendation is a
HOLD command, a hold where its track stops (:mod:`.held`). A plan is not uploaded either over
a command another case has decided since (or in the same cycle) for the same UAS
(:mod:`.overridden`). Pure.
"""

from __future__ import annotations

import math
from dataclasses import replace

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.held import circling_elsewhere, held_plan
from gcs_utm.core.emergency.overridden import newer_command
from gcs_utm.model import (
    AirspaceSnapshot,
    CommandKind,
    FlightPlan,
    Operation,
    OperationId,
    Recommendation,
    RecommendationState,
)

_LIVE = (RecommendationState.PROPOSED, RecommendationState.ACCEPTED, RecommendationState.APPLIED)


def _intended(
    em: EmContext, rec: Recommendation
) -> dict[OperationId, tuple[float, FlightPlan | None]]:
    """The newest plan each other UAS has been recommended (proposed, accepted or applied),
    or None when its newest such recommendation is a HOLD command, with its time."""
    latest: dict[OperationId, tuple[float, FlightPlan | None]] = {}
    cases = [c for c in map(em.case, em.open_threats()) if c is not None]
    # sorted: a set of str iterates in the process's hash order, and of two recommendations
    # created at one time the later one here wins (a run must not depend on PYTHONHASHSEED)
    for rid in sorted({r for c in cases for r in c.rec_ids}):
        r = em.recommendation(rid)
        if r is None or r.operation_id == rec.operation_id or r.state not in _LIVE:
            continue
        plan = r.selected.plan if r.selected is not None else None
        hold = r.command is not None and r.command.kind is CommandKind.HOLD
        if plan is None and not hold:
            continue
        prev = latest.get(r.operation_id)
        if prev is None or r.created_t_s >= prev[0]:
            latest[r.operation_id] = (r.created_t_s, plan)
    return latest


def _others(
    em: EmContext, rec: Recommendation, snapshot: AirspaceSnapshot, until_t_s: float
) -> list[Operation]:
    intended = _intended(em, rec)
    out = []
    # TD's traffic: airborne UAS after their plan hover there, or fly the circle they are
    # seen on (a fixed wing), as when the plan was made
    for op in em.td.others(snapshot, {rec.operation_id}):
        k = op.id
        t_rec, plan = intended.get(k, (-math.inf, None))
        held_now = plan is None and op.plan.created_t_s < t_rec  # told to hold since
        raw = snapshot.operations.get(k, op)
        if held_now or circling_elsewhere(raw, snapshot, em.td.frame):  # where it stops
            held = held_plan(op, snapshot, em.td.frame, until_t_s)
            out.append(op if held is None else replace(op, plan=held))
            continue
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
    newer = newer_command(em, rec)
    if newer:  # a command decided since (or with it) for the same UAS stands (.overridden)
        return f"{rec.id} v{rec.version} overtaken by the command of {newer} for {op.id}"
    plan = replace(plan, operation_id=op.id)
    others = _others(em, rec, snapshot, max(plan.end_t_s, snapshot.t_s) + em.td.config.horizon_s)
    flags = [f for f in em.td.verify(plan, op, others, (), buffered=False) if f]
    if not flags:
        return ""
    return f"{rec.id} v{rec.version} re-checked before its upload: " + "; ".join(flags[:3])
