"""A fixed wing re-timed part-way along a leg goes back onto that leg (pure; docs/autopilots.md,
"Fixed wings: take-off, loiters, landing").

A plan re-timed from a vehicle's progress starts at its position. A multirotor flies straight
from there; a fixed wing does not: its navigation controller tracks the line from the previous
waypoint to the current one (ArduPlane's L1 ``update_waypoint(prev_WP_loc, next_WP_loc)``, its
NAV_LAND's glide from the approach waypoint, PX4's path following) and converges on it within
about its L1 distance. Measured on ArduPlane 4.6 SITL (the nuisance soak's, serve restarted
while the plane landed): 10 m off its landing line when its mission was filed again, on it
45 m further; a straight line from its position to the landing point ran 12-14 m beside it
(UAS_IN_CV). So the plan goes from the position to the point of the leg one L1 distance past
the position's projection on it, then on along the leg.
Not after a take-off (ArduPlane pursues the next waypoint from where it is,
:mod:`.fixed_wing_turn`) nor after a loiter (its exit is modelled, :mod:`.fixed_wing_loiter`).
"""

from __future__ import annotations

import math
from typing import TypeVar

from gcs_utm.services.fixed_wing_point import LOITER_COMMANDS, NAV_TAKEOFF, Point
from gcs_utm.services.fixed_wing_turn import L1_DAMPING, L1_PERIOD_S

P = TypeVar("P", bound=Point)

MIN_OFF_M = 1.0
"""A position this close to the leg is on it: no point is added."""
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


def rejoin(lat_deg: float, lon_deg: float, prev: Point, cur: P) -> list[P]:
    """The point (a modelled one of ``cur``) where a fixed wing at ``lat_deg, lon_deg``,
    flying the leg from ``prev`` to ``cur`` (the current item, with a position of its own),
    is back on that leg; [] when it is on it, past it, or the leg is not tracked from
    ``prev`` (module docstring)."""
    if not cur.explicit or prev.command == NAV_TAKEOFF or prev.command in LOITER_COMMANDS:
        return []
    k = math.cos(math.radians(prev.lat_deg))
    le = (cur.lon_deg - prev.lon_deg) * _M_PER_DEG_LON * k
    ln = (cur.lat_deg - prev.lat_deg) * _M_PER_DEG_LAT
    length = math.hypot(le, ln)
    if length < 1.0:
        return []
    ue, un = le / length, ln / length
    pe = (lon_deg - prev.lon_deg) * _M_PER_DEG_LON * k
    pn = (lat_deg - prev.lat_deg) * _M_PER_DEG_LAT
    along = pe * ue + pn * un
    if abs(pe * un - pn * ue) < MIN_OFF_M or not 0.0 <= along <= length:
        return []
    s = along + L1_DAMPING * L1_PERIOD_S * max(cur.speed_mps, 1.0) / math.pi
    if s >= length - 1.0:
        return []
    alt = prev.alt_amsl_m + (cur.alt_amsl_m - prev.alt_amsl_m) * s / length
    lat = prev.lat_deg + un * s / _M_PER_DEG_LAT
    lon = prev.lon_deg + ue * s / (_M_PER_DEG_LON * k)
    return [cur.moved(lat, lon, alt).synthetic()]
