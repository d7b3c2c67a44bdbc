"""Can the vehicle fly its filed plan at the plan's times? A fixed wing cannot fly slower than
its minimum airspeed (its envelope's ``min_speed_mps``, :mod:`gcs_utm.envelope`): a plan that
asks for it cannot be kept, and the aircraft drifts ahead of it. Filing refuses such a plan
(the scenario loader and the MQTT filing call :func:`plan_speed_problem`).

Leg lengths are 3D, horizontally on a local sphere at the leg's latitude (within 0.5 % of the
geodesic over a plan's legs, far below the margins of an envelope).
"""

from __future__ import annotations

import itertools
import math

from gcs_utm.model import Operation

_EARTH_RADIUS_M = 6_371_008.8
SPEED_TOLERANCE_MPS = 0.05
"""A leg this little below the minimum is rounding in the plan's times, not a slow leg."""


def leg_speeds_mps(op: Operation) -> list[float]:
    """The 3D speed of each leg of ``op``'s plan (m/s); a leg of zero duration counts as
    fast (nothing to hold)."""
    out = []
    wps = op.plan.waypoints
    for a, b in itertools.pairwise(wps):
        lat = math.radians((a.lat_deg + b.lat_deg) / 2.0)
        north = math.radians(b.lat_deg - a.lat_deg) * _EARTH_RADIUS_M
        east = math.radians(b.lon_deg - a.lon_deg) * _EARTH_RADIUS_M * math.cos(lat)
        length = math.sqrt(east * east + north * north + (b.alt_amsl_m - a.alt_amsl_m) ** 2)
        dt = b.t_s - a.t_s
        out.append(length / dt if dt > 0.0 else math.inf)
    return out


def plan_speed_problem(op: Operation) -> str | None:
    """Why ``op``'s plan cannot be flown by its vehicle (a leg below a fixed wing's minimum
    airspeed), naming the operation, the leg and the speeds; None when it can."""
    env = op.performance()
    if env.can_hover or env.min_speed_mps <= 0.0:
        return None
    for k, speed in enumerate(leg_speeds_mps(op), start=1):
        if speed < env.min_speed_mps - SPEED_TOLERANCE_MPS:
            return (
                f"operation {op.id}: leg {k} (waypoint {k} to {k + 1}) is planned at "
                f"{speed:.2f} m/s, below the fixed wing's minimum airspeed "
                f"{env.min_speed_mps:.2f} m/s (its envelope: {env.min_speed_mps:.2f}-"
                f"{env.max_speed_mps:.2f} m/s)"
            )
    return None
