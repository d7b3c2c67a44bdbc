"""A stored plan for a vehicle a service hears flying when it starts (a restarted service).

A plan's times are the clock of the life that made it. A service killed and restarted on the
same store does not run on that clock (at a speed factor above 1 its clock starts where the
store's last time was, not where the previous life's clock would be now), and the vehicle went
on flying while no service watched it. So a new life never judges a flying vehicle by a plan
it did not time: at its first position it re-times the stored plan from the vehicle's progress
(:func:`retimed_at`): the plan's geometry (made when the vehicle was seen taking off, with the
heading of its take-off run) is kept, and its times are shifted so that the point of the plan
nearest the vehicle is where the vehicle is now. This needs neither the mission download nor
MISSION_CURRENT (either can take many seconds on a loaded link); the mission's own re-timing
at the next current item then goes on as for any flight. A vehicle farther than
``max_off_m`` from its stored plan is not matched (None): it is re-planned from its mission.

Pure: positions and times in, a plan out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from gcs_utm.model import FlightPlan, Position, Waypoint4D

_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


def retimed_at(
    plan: FlightPlan,
    position: Position,
    t_s: float,
    *,
    version: int,
    reason: str,
    max_off_m: float,
) -> FlightPlan | None:
    """``plan`` from the vehicle at ``position`` at ``t_s`` on: the waypoints after the point of
    the plan nearest the vehicle (3D, on its legs), their times shifted by the same amount so
    that the plan reaches that point at ``t_s``. None when the plan has no waypoint or the
    vehicle is more than ``max_off_m`` from it."""
    wps = plan.waypoints
    if not wps:
        return None
    leg, u, off_m = _nearest(wps, position)
    if off_m > max_off_m:
        return None
    a = wps[leg]
    b = wps[min(leg + 1, len(wps) - 1)]
    shift_s = t_s - (a.t_s + u * (b.t_s - a.t_s))
    rest = [_at(w, w.t_s + shift_s) for w in wps[leg + 1 :] if w.t_s + shift_s > t_s]
    here = Waypoint4D(
        lat_deg=position.lat_deg, lon_deg=position.lon_deg, alt_amsl_m=position.alt_amsl_m, t_s=t_s
    )
    return FlightPlan(
        operation_id=plan.operation_id,
        version=version,
        waypoints=(here, *rest),
        created_t_s=t_s,
        reason=reason,
    )


def _nearest(wps: Sequence[Waypoint4D], p: Position) -> tuple[int, float, float]:
    """(leg index i, fraction along the leg i -> i+1, 3D distance) of the plan's point nearest
    ``p``; the first of equally near points (a plan that passes a place twice is matched at
    its first pass only when the altitude does not tell them apart)."""
    best = (0, 0.0, _dist3(p, wps[0]))
    for i in range(len(wps) - 1):
        a, b = wps[i], wps[i + 1]
        ax, ay, az = _enu(p, a)
        bx, by, bz = _enu(p, b)
        dx, dy, dz = bx - ax, by - ay, bz - az
        span2 = dx * dx + dy * dy + dz * dz
        u = 0.0 if span2 <= 0.0 else min(1.0, max(0.0, -(ax * dx + ay * dy + az * dz) / span2))
        d = math.sqrt((ax + u * dx) ** 2 + (ay + u * dy) ** 2 + (az + u * dz) ** 2)
        if d < best[2]:
            best = (i, u, d)
    return best


def _enu(origin: Position, w: Waypoint4D) -> tuple[float, float, float]:
    k = math.cos(math.radians(origin.lat_deg))
    return (
        (w.lon_deg - origin.lon_deg) * _M_PER_DEG_LON * k,
        (w.lat_deg - origin.lat_deg) * _M_PER_DEG_LAT,
        w.alt_amsl_m - origin.alt_amsl_m,
    )


def _dist3(p: Position, w: Waypoint4D) -> float:
    return math.sqrt(sum(c * c for c in _enu(p, w)))


def _at(w: Waypoint4D, t_s: float) -> Waypoint4D:
    return Waypoint4D(lat_deg=w.lat_deg, lon_deg=w.lon_deg, alt_amsl_m=w.alt_amsl_m, t_s=t_s)
