"""A plan whose destination lies inside an active geofence: end it outside the fence.

Reroute, direct to goal and next waypoint all lead to the plan's last waypoint; when that
point lies inside a fence grown by the UAS's volume none of them has a path, and before this
the UAS was offered nothing (a fixed wing bound for a point inside a fence was told to hold,
and circled through the traffic around it). :func:`goal_outside` keeps the plan's free
waypoints (blocked stretches replaced by A* paths, as a reroute does) and moves the end point
to the closest point outside every obstacle, ``escape_distance_m`` beyond the border; for a
vehicle that cannot hover, a further turn radius, so that the circle it flies round its last
waypoint stays outside too. Verified and scored like every other candidate. Pure."""

from __future__ import annotations

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.deconfliction.router import Router


def destination_blocked(router: Router) -> bool:
    """Does the plan's last waypoint lie inside an obstacle (an inflated fence)?"""
    return not router.planner.free(router.lp.xyz()[-1][:2])


def goal_outside(router: Router) -> tuple[LocalPlan, int] | None:
    """The plan with its destination moved to the closest point outside every obstacle
    (None when the destination is free, or when no path reaches the new end point)."""
    if not destination_blocked(router):
        return None
    op = router.op
    env = op.performance()
    extra_m = router.escape_m + (0.0 if env.can_hover else env.turn_radius_m)
    lp = router.lp
    dest = lp.xyz()[-1]
    out = router.planner.exit_point(dest[:2], extra_m)
    e, n = lp.e.copy(), lp.n.copy()
    e[-1], n[-1] = float(out[0]), float(out[1])
    moved = LocalPlan(e, n, lp.z.copy(), lp.t.copy())
    return Router(op, router.planner, router.now, router.cur, moved, router.escape_m).reroute()
