"""A hovering UAS whose plan moves on: it stays where it is until it gets a new plan.

A multirotor that EM has held (or that waits, stopped, for any other reason) is at rest while
its plan, re-timed from its progress (:mod:`.retime`), moves on from where it stopped: TD took
it to leave at once at its plan's speed. A new plan then started where the UAS would have
been by its start time, up to the whole answer window of flight ahead of a vehicle that in
fact had not moved: a held multirotor given a plan round a fixed wing circling at its end
point was 33 m behind it when it started, was held again for that (out of its operation
volume) and stopped in the circle's path (46.8 m against 50 m,
enc_1_0155_endpoint_crossing).

:func:`at_rest` gives such a UAS, for one TD call, the plan it flies: where it is until
``resume_t_s`` (the earliest time it can have a new plan), then its plan shifted by the wait.
New plans, their lead-in and the traffic every candidate is checked against start from there.
A UAS counts as at rest when it can hover, its fresh track moves slower than
:data:`AT_REST_MPS` and its plan at the snapshot time moves faster than :data:`MOVING_MPS`
horizontally. Pure: time comes from the snapshot, positions go through the airspace frame.
"""

from __future__ import annotations

import math
from dataclasses import replace

from gcs_utm.geo import LocalFrame
from gcs_utm.model import AirspaceSnapshot, FlightPlan, Operation, Track, Waypoint4D

AT_REST_MPS = 0.5
"""A track slower than this (horizontally and vertically) is hovering."""
MOVING_MPS = 1.0
"""A plan faster than this at the snapshot time expects the UAS to be moving."""


def _track_of(op: Operation, snapshot: AirspaceSnapshot) -> Track | None:
    for tr in snapshot.tracks.values():
        if tr.operation_id == op.id and not tr.stale:
            return tr
    return None


def _segment(plan: FlightPlan, t_s: float) -> int | None:
    """The index k of the leg that holds ``t_s`` (waypoint k at or before it, k + 1 after)."""
    wps = plan.waypoints
    for k in range(len(wps) - 1):
        if wps[k].t_s <= t_s < wps[k + 1].t_s:
            return k
    return None


def _at(a: Waypoint4D, b: Waypoint4D, t_s: float) -> Waypoint4D:
    u = (t_s - a.t_s) / (b.t_s - a.t_s)
    return Waypoint4D(
        lat_deg=a.lat_deg + u * (b.lat_deg - a.lat_deg),
        lon_deg=a.lon_deg + u * (b.lon_deg - a.lon_deg),
        alt_amsl_m=a.alt_amsl_m + u * (b.alt_amsl_m - a.alt_amsl_m),
        t_s=t_s,
    )


def waiting_plan(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, resume_t_s: float
) -> FlightPlan | None:
    """``op``'s plan as a UAS at rest flies it (see the module docstring), or None when it is
    not at rest or its plan does not move now."""
    now = snapshot.t_s
    if resume_t_s <= now or not op.performance().can_hover:
        return None
    tr = _track_of(op, snapshot)
    if tr is None or tr.ground_speed_mps >= AT_REST_MPS or abs(tr.vel_enu_mps[2]) >= AT_REST_MPS:
        return None
    plan = op.plan
    k = _segment(plan, now)
    if k is None:
        return None
    a, b = plan.waypoints[k], plan.waypoints[k + 1]
    ea, na = frame.point_to_local(a.lat_deg, a.lon_deg)
    eb, nb = frame.point_to_local(b.lat_deg, b.lon_deg)
    if math.hypot(eb - ea, nb - na) / (b.t_s - a.t_s) <= MOVING_MPS:
        return None
    here = _at(a, b, now)
    wait_s = resume_t_s - now
    before = [w for w in plan.waypoints if w.t_s < now]
    after = [replace(w, t_s=w.t_s + wait_s) for w in plan.waypoints if w.t_s > now]
    return replace(plan, waypoints=(*before, here, replace(here, t_s=resume_t_s), *after))


def at_rest(
    snapshot: AirspaceSnapshot,
    frame: LocalFrame,
    start_t_s: float | None,
    lead_in_from_t_s: float | None,
) -> AirspaceSnapshot:
    """``snapshot`` with the plan of every UAS at rest replaced by :func:`waiting_plan` up to
    the earliest time it can have a new plan: ``lead_in_from_t_s``, else the new plans'
    ``start_t_s`` (``snapshot`` itself when neither is given or no UAS is at rest)."""
    resume_t_s = start_t_s if lead_in_from_t_s is None else lead_in_from_t_s
    if resume_t_s is None:
        return snapshot
    ops = dict(snapshot.operations)
    changed = False
    for op_id, op in snapshot.operations.items():
        plan = waiting_plan(op, snapshot, frame, resume_t_s)
        if plan is not None:
            ops[op_id] = replace(op, plan=plan)
            changed = True
    return replace(snapshot, operations=ops) if changed else snapshot
