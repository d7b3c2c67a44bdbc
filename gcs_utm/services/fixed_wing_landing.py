"""A PX4 fixed wing's landing approach from a NAV_LOITER_TO_ALT (pure; docs/autopilots.md,
"Fixed wings: take-off, loiters, landing").

QGroundControl's fixed-wing landing pattern is DO_LAND_START, NAV_LOITER_TO_ALT, NAV_LAND. PX4
v1.15 takes the loiter's centre as the approach entrance of its landing: once at the loiter's
altitude it goes on round the circle to the point of it towards the landing point, and glides
from there along the line from the centre to the landing point. Measured on PX4 v1.15.2 SIH
(loiter 80 m clockwise, 854 m from the landing point, 40 -> 30 m): it entered the circle
from the north-east, went round it clockwise to the point towards the landing point (68 m
from the centre, 3 m from that line) and followed that line within 3 m to touchdown. A
straight line from the circle's last modelled point (or from the tangent through the
landing point) to the landing point lay up to 50 m off its path (UAS_OUT_OV).
"""

from __future__ import annotations

import math

_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0
STEP_RAD = math.pi / 12.0
"""Points every 15 degrees (a chord 0.9 % of the radius inside the arc): a plan from NAV_LAND
starts at the one nearest the plane, wherever on the circle NAV_LAND became current."""


def landing_exit(
    centre_deg: tuple[float, float],
    radius_m: float,
    last_deg: tuple[float, float],
    land_deg: tuple[float, float],
) -> list[tuple[float, float]]:
    """(lat, lon) points on the circle round ``centre_deg`` (``radius_m``; negative:
    counter-clockwise, else clockwise) from ``last_deg`` (a point of the circle) on to its
    point towards ``land_deg``, that point last; [] when the landing point is inside the
    circle (PX4 rejects that mission) or the circle is too small to model."""
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
    exit_rad = math.atan2(ln, le)
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
