"""Where a fixed wing under a hold or go-to command is when its new plan starts.

TD starts a new plan where the UAS will be at the plan's start: on its plan then, offset by
how far it is off it now (:meth:`.deconfliction.context.Context.start_xyz`). A fixed wing
that an immediate command has sent off its plan does not follow it: it circles where it was
held, or flies towards its go-to point. Its new plan then started up to a plan-leg's flight
from the aircraft, on the far side of a fence: a fixed wing turned away at 77 s was given a
plan back round a fence at 80 s starting 56 m from the track's extrapolation, turned back on its
radius to reach it and flew 5 s inside the fence (``enc_3_0409_late_near_threshold``); one
held at 124 s got a "leave the fence" plan starting where its filed plan (7 s ahead)
crossed the fence it was circling clear of, and flew it in (``enc_3_0235``).

:func:`commanded_snapshot` gives the UAS being decided, for one TD call, the plan it flies
while its command is in force (as :mod:`.deconfliction.at_rest` does for a multirotor at
rest): from its track now, held where it is (the centre of the circle it flies) or straight
towards its go-to point at its ground speed, until the new plan's start, then the rest of its
plan shifted by that time. A UAS is under a command when the newest of its recommendations
that is accepted or applied is a HOLD or GOTO command, newer than its plan. Pure.
"""

from __future__ import annotations

import math
from dataclasses import replace

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    FlightPlan,
    Operation,
    OperationId,
    RecommendationState,
    Waypoint4D,
)

_IN_FORCE = (RecommendationState.ACCEPTED, RecommendationState.APPLIED)
_CIRCLING = (CommandKind.HOLD, CommandKind.GOTO)


def command_in_force(em: EmContext, op: Operation) -> Command | None:
    """The HOLD or GOTO command ``op`` flies now (see the module docstring), or None."""
    newest = None
    for r in em.recs.values():
        if r.operation_id != op.id or r.state not in _IN_FORCE:
            continue
        t = r.state_t_s if r.state_t_s is not None else r.created_t_s
        if newest is None or t >= newest[0]:
            newest = (t, r)
    if newest is None:
        return None
    t, rec = newest
    cmd = rec.command
    if cmd is None or cmd.kind not in _CIRCLING or op.plan.created_t_s >= t:
        return None
    return cmd


def commanded_plan(
    op: Operation, cmd: Command, snapshot: AirspaceSnapshot, frame: LocalFrame, resume_t_s: float
) -> FlightPlan | None:
    """``op``'s plan as the fixed wing flies it under ``cmd`` until ``resume_t_s`` (see the
    module docstring), or None (no fresh track, or nothing to wait for)."""
    now = snapshot.t_s
    tr = next(
        (t for t in snapshot.tracks.values() if t.operation_id == op.id and not t.stale), None
    )
    if tr is None or resume_t_s <= now:
        return None
    here = Waypoint4D(lat_deg=tr.lat_deg, lon_deg=tr.lon_deg, alt_amsl_m=tr.alt_amsl_m, t_s=now)
    there = replace(here, t_s=resume_t_s)
    if cmd.kind is CommandKind.GOTO and cmd.target is not None:
        e0, n0 = frame.point_to_local(tr.lat_deg, tr.lon_deg)
        e1, n1 = frame.point_to_local(cmd.target.lat_deg, cmd.target.lon_deg)
        dist_m = math.hypot(e1 - e0, n1 - n0)
        run_m = min(dist_m, tr.ground_speed_mps * (resume_t_s - now))
        u = run_m / dist_m if dist_m > 1e-6 else 0.0
        lat, lon = frame.point_to_wgs84(e0 + u * (e1 - e0), n0 + u * (n1 - n0))
        env = op.performance()
        dz = cmd.target.alt_amsl_m - tr.alt_amsl_m
        rate = env.climb_rate_mps if dz > 0.0 else env.descent_rate_mps
        dz = math.copysign(min(abs(dz), rate * (resume_t_s - now)), dz)
        there = Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=tr.alt_amsl_m + dz, t_s=resume_t_s)
    wait_s = resume_t_s - now
    before = [w for w in op.plan.waypoints if w.t_s < now]
    after = [replace(w, t_s=w.t_s + wait_s) for w in op.plan.waypoints if w.t_s > now]
    return replace(op.plan, waypoints=(*before, here, there, *after))


def commanded_snapshot(
    em: EmContext, snapshot: AirspaceSnapshot, op_id: OperationId, resume_t_s: float
) -> AirspaceSnapshot:
    """``snapshot`` with the plan of ``op_id``, a fixed wing under a HOLD or GOTO command,
    replaced by :func:`commanded_plan` (``snapshot`` itself otherwise)."""
    op = snapshot.operations.get(op_id)
    if op is None or op.performance().can_hover:
        return snapshot
    cmd = command_in_force(em, op)
    if cmd is None:
        return snapshot
    plan = commanded_plan(op, cmd, snapshot, em.td.frame, resume_t_s)
    if plan is None:
        return snapshot
    return replace(snapshot, operations={**snapshot.operations, op_id: replace(op, plan=plan)})
