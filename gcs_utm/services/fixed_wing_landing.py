"""A PX4 fixed wing's landing approach from a NAV_LOITER_TO_ALT (pure; docs/autopilots.md,
"Fixed wings: take-off, loiters, landing").

PX4's fixed-wing landing pattern (QGroundControl's: DO_LAND_START, NAV_LOITER_TO_ALT, NAV_LAND)
orbits the loiter until its altitude, then leaves the circle on the tangent that passes
through the landing point and glides along it to touchdown: its approach is
``sqrt(d^2 - r^2)`` long (PX4 v1.15 ``FeasibilityChecker::checkFixedWindLandApproach``, which
rejects a landing point inside the orbit). Modelled as the plane flies it: from the circle's
last modelled point on round the circle, in its sense, to that tangent point, then the
straight descent to the landing point. A straight line from an arbitrary point of the circle
to the landing point lies up to a diameter off the path.
"""

from __future__ import annotations

import math

_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0
STEP_RAD = math.pi / 4.0  # points every 45 degrees, as the circles of fixed_wing_plan


def tangent_exit(
    centre_deg: tuple[float, float],
    radius_m: float,
    last_deg: tuple[float, float],
    land_deg: tuple[float, float],
) -> list[tuple[float, float]]:
    """(lat, lon) points on the circle round ``centre_deg`` (``radius_m``; negative:
    counter-clockwise, else clockwise) from ``last_deg`` (a point of the circle) on to the
    tangent point towards ``land_deg``, that point last; [] when the landing point is inside
    the circle (PX4 rejects that mission) or the circle is too small to model."""
    r = abs(radius_m)
    k = math.cos(math.radians(centre_deg[0]))

    def east_north(p: tuple[float, float]) -> tuple[float, float]:
        return (
            (p[1] - centre_deg[1]) * _M_PER_DEG_LON * k,
            (p[0] - centre_deg[0]) * _M_PER_DEG_LAT,
        )

    le, ln = east_north(land_deg)
    d = math.hypot(le, ln)
    if r < 1.0 or d <= r:
        return []
    sense = 1.0 if radius_m < 0.0 else -1.0  # the angle (from east) increases anticlockwise
    # clockwise the tangent towards the landing point is at phi + acos(r/d), anticlockwise
    # at phi - acos(r/d) (the velocity there points at it)
    exit_rad = math.atan2(ln, le) - sense * math.acos(r / d)
    at_e, at_n = east_north(last_deg)
    at_rad = math.atan2(at_n, at_e)
    to_go = (sense * (exit_rad - at_rad)) % (2.0 * math.pi)
    out: list[tuple[float, float]] = []
    steps = math.floor(to_go / STEP_RAD)
    for j in range(1, steps + 1):
        if to_go - j * STEP_RAD < 1e-6:
            break
        out.append(_on(centre_deg, r, at_rad + sense * j * STEP_RAD, k))
    out.append(_on(centre_deg, r, exit_rad, k))
    return out


def _on(centre_deg: tuple[float, float], r: float, a: float, k: float) -> tuple[float, float]:
    return (
        centre_deg[0] + r * math.sin(a) / _M_PER_DEG_LAT,
        centre_deg[1] + r * math.cos(a) / (_M_PER_DEG_LON * k),
    )
