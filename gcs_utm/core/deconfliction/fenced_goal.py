"""A plan whose destination lies inside an active geofence: end it outside the fence.

Reroute, direct to goal and next waypoint all lead to the plan's last waypoint; when that
point lies inside a fence grown by the UAS's volume none of them has a path, and before this
the UAS was offered nothing (a fixed wing bound for a point inside a fence was told to hold,
and circled through the traffic around it). :func:`goal_outside` keeps the plan's free
waypoints (blocked stretches replaced by A* paths, as a reroute does) and moves the end point
to the closest point outside every obstacle, ``escape_distance_m`` beyond the border; for a
vehicle that cannot hover, a further turn radius, so that the circle it flies round its last
waypoint stays outside too.

A fixed wing's destination is blocked as well when it lies outside every fence but the
circle it flies round it once the plan has ended (its turn radius) comes inside one: every
route to it ends with that circle (an end point 52 m from a fence, circled at 80 m, entered
it 5 s after the plan's end). The end point then moves away from the fence until the circle
clears it by ``escape_distance_m``. The circle is entered from its centre on the last leg's
course and swings out on the turn before it settles (:func:`.end_circle.end_ring`): that
entry coming inside an obstacle blocks the destination too, and an end point outside the
fences then moves by as much room as the entry needs (up to its reach) instead of the
radius. Verified and scored like every other candidate. Pure."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString, Point

from gcs_utm.core.deconfliction.geometry import NODE_EPS_M, LocalPlan
from gcs_utm.core.deconfliction.router import Router
from gcs_utm.core.monitoring import end_circle
from gcs_utm.model import FloatArray


def circle_radius_m(router: Router) -> float:
    """The radius of the circle the UAS flies round its last waypoint once its plan has
    ended: its turn radius if it cannot hover, else 0."""
    env = router.op.performance()
    return 0.0 if env.can_hover else env.turn_radius_m


def _entry_ring(router: Router) -> FloatArray | None:
    """(M, 4) the entry and circle round the plan's last waypoint (:func:`.end_circle.end_ring`
    at the turn radius), or None (a vehicle that hovers, a plan that never moves)."""
    radius_m = circle_radius_m(router)
    if radius_m <= 0.0:
        return None
    lp = router.lp
    return end_circle.end_ring(np.stack([lp.e, lp.n, lp.z, lp.t], axis=1), radius_m)


def room_m(router: Router) -> float:
    """How far the UAS flies from its last waypoint once its plan has ended: the reach of
    its entry and circle (the turn radius when the plan never moves), 0 if it hovers."""
    ring = _entry_ring(router)
    if ring is None:
        return circle_radius_m(router)
    dest = router.lp.xyz()[-1]
    return max(float(np.hypot(*(ring[:, :2] - dest[:2]).T).max()), circle_radius_m(router))


def destination_blocked(router: Router) -> bool:
    """Does the plan's last waypoint lie inside an obstacle (an inflated fence), or, for a
    fixed wing, the circle it flies round that point, or its entry, come inside one?"""
    dest = router.lp.xyz()[-1][:2]
    if not router.planner.free(dest):
        return True
    radius_m = circle_radius_m(router)
    obstacles = router.planner.obstacles
    if radius_m <= 0.0 or not obstacles:
        return False
    union = shapely.union_all(obstacles)
    if float(union.distance(Point(dest[0], dest[1]))) < radius_m:
        return True
    ring = _entry_ring(router)
    return ring is not None and bool(union.intersects(LineString(ring[:, :2])))


def goal_outside(router: Router) -> tuple[LocalPlan, int] | None:
    """The plan with its destination moved to the closest point outside every obstacle
    (None when the destination is free, or when no path reaches the new end point)."""
    if not destination_blocked(router):
        return None
    lp = router.lp
    dest = lp.xyz()[-1]
    if router.planner.free(dest[:2]):
        out = _entry_clear(router, dest[:2])
        if out is None:
            return None
    else:
        out = router.planner.exit_point(dest[:2], router.escape_m + circle_radius_m(router))
    e, n = lp.e.copy(), lp.n.copy()
    e[-1], n[-1] = float(out[0]), float(out[1])
    moved = LocalPlan(e, n, lp.z.copy(), lp.t.copy())
    return Router(
        op=router.op,
        planner=router.planner,
        now=router.now,
        cur=router.cur,
        lp=moved,
        escape_m=router.escape_m,
    ).reroute()


ROOM_STEP_M = 10.0
"""Step by which the room kept round a moved end point grows, from the circle's radius to
the entry's reach, until the entry and circle round the new point clear every obstacle."""


def _entry_clear(router: Router, p: FloatArray) -> FloatArray | None:
    """The closest point to ``p`` whose circle, and its entry on the last leg's course, clear
    every obstacle by ``escape_m`` (:func:`_circle_clear` with the least room that does,
    from the turn radius up to the entry's reach), or None."""
    radius_m, reach_m = circle_radius_m(router), room_m(router)
    lp = router.lp
    kept = shapely.union_all(router.planner.obstacles).buffer(router.escape_m)
    room = radius_m
    while True:
        out = _circle_clear(router, p, router.escape_m + room)
        if out is None or room >= reach_m:
            return out
        e, n = lp.e.copy(), lp.n.copy()
        e[-1], n[-1] = float(out[0]), float(out[1])
        ring = end_circle.end_ring(np.stack([e, n, lp.z, lp.t], axis=1), radius_m)
        if ring is None or not kept.intersects(LineString(ring[:, :2])):
            return out
        room = min(room + ROOM_STEP_M, reach_m)


def _circle_clear(router: Router, p: FloatArray, extra_m: float) -> FloatArray | None:
    """The closest point to ``p`` (outside every obstacle) at least ``extra_m`` from all of
    them, or None when the nearest such border point is still too close (between fences)."""
    union = shapely.union_all(router.planner.obstacles)
    grown = union.buffer(NODE_EPS_M + extra_m, join_style="mitre", mitre_limit=2.0)
    boundary = grown.boundary
    q = boundary.interpolate(boundary.project(Point(p[0], p[1])))
    if float(union.distance(q)) < extra_m:
        return None
    out: FloatArray = shapely.get_coordinates(q)[0]
    return out
