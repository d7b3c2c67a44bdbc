"""Single-UAS alternatives of Tactical Deconfliction (paper §4.5): A* on a visibility graph of
inflated geofences: reroute around a crossing, escape from inside, direct to goal, back to
plan, next waypoint, return home, nearest reachable landing site. Every new plan starts at
the context's start time (:func:`.context.start_time`) where the UAS will be then; TD
verifies and scores the candidates like every other. Pure."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Sequence

import numpy as np

from gcs_utm.core.deconfliction.astar import VisibilityPlanner
from gcs_utm.core.deconfliction.context import Context, Dropped, Queued
from gcs_utm.core.deconfliction.fence_exit import leave_on_receipt
from gcs_utm.core.deconfliction.fenced_goal import destination_blocked, goal_outside
from gcs_utm.core.deconfliction.geometry import LocalPlan, merged_obstacles, relevant_fences
from gcs_utm.core.deconfliction.router import Router
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FloatArray,
    Geofence,
    Maneuver,
    Operation,
    OperationId,
    Threat,
)


def single_candidates(
    ctx: Context,
    threat: Threat,
    operation_id: OperationId,
    snapshot: AirspaceSnapshot,
    *,
    maneuvers: Collection[Maneuver] | None = None,
    extra_geofences: Sequence[Geofence] = (),
) -> tuple[list[Queued], list[Alternative]]:
    """Single-UAS candidates (A*) and the list their alternatives go to once verified;
    ``maneuvers`` limits which are generated (None = all that apply), ``extra_geofences``
    are fences not yet in the snapshot (an alert area EM is about to create). New plans
    start at the context's start time from where the UAS will be then."""
    queue: list[Queued] = []
    op = snapshot.operations.get(operation_id)
    if op is None:
        return queue, []
    want = set(maneuvers) if maneuvers is not None else set(Maneuver)
    t0 = ctx.start_t_s
    cfg = ctx.config
    geofences = tuple(snapshot.geofences) + tuple(
        g for g in extra_geofences if g.id not in {f.id for f in snapshot.geofences}
    )
    if threat.area is not None and threat.area.id not in {g.id for g in geofences}:
        geofences += (threat.area,)
    # A dynamic geofence drawn around this UAS (jamming, link loss) does not apply to it.
    geofences = tuple(g for g in geofences if g.applies_to(op.id))
    fences = ctx.local_fences(geofences)
    lp = ctx.local_plan(op.plan).after(t0)
    cur = ctx.start_xyz(op, snapshot)
    zs = np.concatenate([lp.z, [cur[2]]])
    ov = op.operational_volume_m
    active = relevant_fences(
        fences,
        t0,
        max(t0 + cfg.horizon_s, float(lp.t[-1])),
        float(zs.min()) - ov,
        float(zs.max()) + ov,
    )
    planner = VisibilityPlanner(
        merged_obstacles(active, ov + cfg.clearance_margin_m, cfg.cylinder_sides)
    )
    early = leave_on_receipt(ctx, op, snapshot, planner)  # do not fly further in first
    if early is not ctx:
        ctx, t0 = early, early.start_t_s
        lp = ctx.local_plan(op.plan).after(t0)
        cur = ctx.start_xyz(op, snapshot)
    outsiders = ctx.others(snapshot, {op.id})
    out: list[Alternative] = []

    def add(man: Maneuver, route: tuple[LocalPlan, int] | None, detail: str) -> None:
        if route is None:
            queue.append(Dropped(operation_id=op.id, maneuver=man, reason="no path"))
            return
        new, verify_from = route
        queue.append(
            ctx.candidate(
                op,
                man,
                new,
                lp,
                geofences=geofences,
                fences=fences,
                outsiders=outsiders,
                lowest_priority=op.priority,
                detail=detail,
                dest=out,
                verify_from=verify_from,
            )
        )

    router = Router(op, planner, t0, cur, lp, cfg.escape_distance_m)
    if router.inside():
        _from_inside(ctx, router, want, add)
    else:
        _routes(op, router, want, add)
    _abandon(ctx, op, router, want, add, queue)
    return queue, out


def _from_inside(
    ctx: Context,
    router: Router,
    want: set[Maneuver],
    add: Callable[[Maneuver, tuple[LocalPlan, int] | None, str], None],
) -> None:
    """Inside a geofence grown by the UAS's volume: leave by the closest border point and
    rejoin the plan (escape) or, whatever the plan does (its destination may lie inside the
    fence), leave and hold outside; return home and the landing sites leave first too
    (:func:`_abandon`, :meth:`Router.land_at`). So the UAS always has a way out offered."""
    if Maneuver.ESCAPE in want:
        add(
            Maneuver.ESCAPE,
            router.escape(),
            "leave by the closest border point, then rejoin the plan",
        )
    if Maneuver.HOLD in want:
        add(
            Maneuver.HOLD,
            router.hold_outside(ctx.config.horizon_s),
            "leave by the closest border point and hold there",
        )


def _routes(
    op: Operation,
    router: Router,
    want: set[Maneuver],
    add: Callable[[Maneuver, tuple[LocalPlan, int] | None, str], None],
) -> None:
    """The manoeuvres that stay on the mission: reroute, direct to goal, back to the
    plan, next waypoint."""
    lp = router.lp
    if Maneuver.REROUTE in want:
        add(Maneuver.REROUTE, router.reroute(), "replace the crossing part of the plan")
        if destination_blocked(router):  # the others lead there too: end outside the fence
            add(Maneuver.REROUTE, goal_outside(router), "end at the closest point outside")
    if Maneuver.DIRECT_TO_GOAL in want:
        add(
            Maneuver.DIRECT_TO_GOAL,
            router.to_point(lp.xyz()[-1]),
            "direct to the final waypoint",
        )
    off_plan = router.distance_to_plan() > op.flight_geometry_m
    if Maneuver.BACK_TO_PLAN in want and off_plan:
        add(
            Maneuver.BACK_TO_PLAN,
            router.back_to_plan(),
            "back to the closest point of the plan",
        )
    if Maneuver.NEXT_WAYPOINT in want and len(lp) > 1:
        add(Maneuver.NEXT_WAYPOINT, router.next_waypoint(), "straight to the next waypoint")


def _abandon(  # noqa: PLR0917 - private helper
    ctx: Context,
    op: Operation,
    router: Router,
    want: set[Maneuver],
    add: Callable[[Maneuver, tuple[LocalPlan, int] | None, str], None],
    queue: list[Queued],
) -> None:
    """The manoeuvres that give the mission up: return home, nearest landing site; a site
    out of reach is dropped to ``queue`` (in order with what ``add`` queues)."""
    t0 = router.now
    if Maneuver.RETURN_HOME in want:
        route = router.land_at(_home(ctx, op))
        left = _endurance_left(ctx, op, t0)
        if route is not None and left is not None and route[0].t[-1] - t0 > left:
            queue.append(
                Dropped(
                    operation_id=op.id,
                    maneuver=Maneuver.RETURN_HOME,
                    reason=f"home not reachable with {left:.0f} s of endurance left",
                )
            )
        else:
            how = "land" if op.performance().can_hover else "circle above it"
            add(Maneuver.RETURN_HOME, route, f"return home and {how}")
    if Maneuver.LANDING_SITE in want and op.landing_sites:
        best = _landing(ctx, op, router, t0)
        if best is None:
            queue.append(
                Dropped(
                    operation_id=op.id,
                    maneuver=Maneuver.LANDING_SITE,
                    reason="no landing site reachable",
                )
            )
        else:
            add(Maneuver.LANDING_SITE, best[0], best[1])


def _home(ctx: Context, op: Operation) -> FloatArray:
    if op.home is not None:
        e, n = ctx.frame.point_to_local(op.home.lat_deg, op.home.lon_deg)
        return np.array([e, n, op.home.alt_amsl_m])
    return np.asarray(ctx.local_plan(op.plan).xyz()[0], dtype=np.float64)


def _endurance_left(ctx: Context, op: Operation, now: float) -> float | None:
    """Usable flight time left (endurance counted from the plan start, minus the
    reserve), or None when the endurance is unknown."""
    if op.endurance_s is None:
        return None
    left = op.endurance_s - max(0.0, now - op.plan.start_t_s)
    return left * (1.0 - ctx.config.landing_reserve_fraction)


def _landing(
    ctx: Context, op: Operation, router: Router, now: float
) -> tuple[tuple[LocalPlan, int], str] | None:
    """The landing site reached soonest that the remaining endurance covers (with the
    reserve), when the endurance is known (``Operation.endurance_s`` counted from the
    plan start)."""
    remaining = _endurance_left(ctx, op, now)
    best: tuple[tuple[LocalPlan, int], str] | None = None
    best_t = math.inf
    for k, site in enumerate(op.landing_sites):
        e, n = ctx.frame.point_to_local(site.lat_deg, site.lon_deg)
        route = router.land_at(np.array([e, n, site.alt_amsl_m]))
        if route is None:
            continue
        dur = float(route[0].t[-1] - now)
        if remaining is not None and dur > remaining:
            continue
        if dur < best_t:
            best_t = dur
            how = "land at" if op.performance().can_hover else "circle above"
            best = (route, f"{how} site {k} in {dur:.0f} s")
    return best
