"""Can the vehicle fly its filed plan at the plan's times? A fixed wing cannot fly slower than
its minimum airspeed (its envelope's ``min_speed_mps``, :mod:`gcs_utm.envelope`): a plan that
asks for it cannot be kept, and the aircraft drifts ahead of it. No vehicle climbs or descends
faster than its envelope's ``climb_rate_mps`` / ``descent_rate_mps``: a leg that asks for it
reaches its waypoint too high or too low (a fixed wing then circles down or up to it, off its
plan). Filing refuses such a plan (the scenario loader and the MQTT filing call
:func:`plan_problem`).

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


RATE_TOLERANCE = 1.02
"""A leg this little above a vertical rate is rounding (centimetres, milliseconds), not a
steep leg: the slack Tactical Deconfliction's own envelope check allows
(``core.deconfliction.safety.SPEED_TOLERANCE``)."""
MIN_LEG_S = 0.5
"""A leg shorter than this is rated as if it took this long: a join of two legs a few
milliseconds long with a centimetre of altitude is not a climb; a jump of metres is."""


def leg_vertical_rates_mps(op: Operation) -> list[float]:
    """The vertical rate of each leg of ``op``'s plan (m/s, positive up), a leg shorter than
    :data:`MIN_LEG_S` rated over that time."""
    wps = op.plan.waypoints
    return [
        (b.alt_amsl_m - a.alt_amsl_m) / max(b.t_s - a.t_s, MIN_LEG_S)
        for a, b in itertools.pairwise(wps)
    ]


def plan_rate_problem(op: Operation) -> str | None:
    """Why ``op``'s plan cannot be flown by its vehicle (a leg climbing or descending faster
    than its envelope allows), naming the operation, the leg, the rate and the limit; None
    when it can."""
    env = op.performance()
    kind = op.vehicle_kind.value.replace("_", " ")
    for k, rate in enumerate(leg_vertical_rates_mps(op), start=1):
        word, limit = (
            ("climbs", env.climb_rate_mps) if rate > 0.0 else ("descends", env.descent_rate_mps)
        )
        if abs(rate) > limit * RATE_TOLERANCE:
            return (
                f"operation {op.id}: leg {k} (waypoint {k} to {k + 1}) {word} at "
                f"{abs(rate):.2f} m/s, faster than its envelope's {limit:.2f} m/s "
                f"({kind}: climb {env.climb_rate_mps:.2f} m/s, descent "
                f"{env.descent_rate_mps:.2f} m/s)"
            )
    return None


def plan_problem(op: Operation) -> str | None:
    """Why ``op``'s plan cannot be flown by its vehicle (:func:`plan_speed_problem`, then
    :func:`plan_rate_problem`); None when it can. Filing refuses a plan with a problem."""
    return plan_speed_problem(op) or plan_rate_problem(op)


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
