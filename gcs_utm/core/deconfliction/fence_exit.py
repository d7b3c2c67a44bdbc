"""A hovering UAS that its plan would carry into a fence leaves from where it gets the plan.

A new plan starts at the context's start time (the answer, the upload and a margin ahead)
where the UAS will be then: on its plan as flown, with timed lead-in points back to the
earliest time it can have the plan (:meth:`.context.Context.lead_in`). When that start point
lies inside a geofence grown by the UAS's volume, every way out (escape, hold outside, return
home, a landing site: :func:`.single.single_candidates`) starts there, its leg out unverified
as from inside a fence, and the lead-in before it, along the plan that crosses the fence,
flies the UAS further in first. A multirotor held 7 m short of a fence that its filed plan
crosses was given an escape whose lead-in took it 5 m inside before it turned back out
(``enc_5_0036_fence_head_on``, UAS2, after EM's immediate hold: ``emergency/fence_late.py``).

:func:`leave_on_receipt` starts such a vehicle's new plans at the earliest time it can have
them, from where it is then (no lead-in): a vehicle that can hover flies its first waypoint
from there, and the way out begins before its plan carries it in. A fixed wing keeps the
start ahead (it flies on meanwhile, whatever it is told). Pure."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.core.deconfliction.astar import VisibilityPlanner
from gcs_utm.core.deconfliction.context import Context
from gcs_utm.model import AirspaceSnapshot, Operation


def leave_on_receipt(
    ctx: Context, op: Operation, snapshot: AirspaceSnapshot, planner: VisibilityPlanner
) -> Context:
    """``ctx`` with new plans starting at the lead-in's first time and no lead-in, when
    ``op`` can hover and its start point lies inside one of ``planner``'s obstacles (the
    geofences grown by its volume); else ``ctx`` itself."""
    lead = ctx.lead
    if lead is None or lead.from_t_s >= ctx.start_t_s or not op.performance().can_hover:
        return ctx
    if planner.free(ctx.start_xyz(op, snapshot)[:2]):
        return ctx
    return replace(ctx, start_t_s=max(snapshot.t_s, lead.from_t_s), lead=None)
