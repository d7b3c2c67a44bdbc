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

A PX4 plane leaves a loiter where its time is up, which the plan places from the speed it is
timed at: filed at 22 m/s, the soak's PX4 SIH plane (14.5 m/s) left its circle about 150 deg
before the modelled exit, and the plan re-timed then ran from its position straight to the
modelled exit's point on the centre's line, 35 m beside the plane turning onto that line
from the circle's tangent (UAS_OUT_OV, an auto-accepted back_to_plan). Re-timed with its
course, the exit turn is made from where it is (:func:`rejoin_rest`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeVar

from gcs_utm.services.fixed_wing_point import LOITER_COMMANDS, NAV_TAKEOFF, Point
from gcs_utm.services.fixed_wing_turn import (
    L1_DAMPING,
    L1_PERIOD_S,
    PX4_PERIOD_S,
    PX4_ROLL_LIMIT_DEG,
    PX4_TRIM_MPS,
    takeoff_turn,
)

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


def rejoin_rest(
    lat_deg: float, lon_deg: float, course_deg: float | None, prev: Point, rest: Sequence[P]
) -> list[P]:
    """``rest`` (the plan's points from the current item on) for a fixed wing at ``lat_deg,
    lon_deg`` that flew ``prev`` last: after a loiter with a modelled exit, when its course is
    known (PX4), that exit made from where it is (:func:`exit_from`); else the point where it
    is back on its leg (:func:`rejoin`) first."""
    if not rest:
        return []
    if prev.command in LOITER_COMMANDS and not rest[0].explicit:
        if course_deg is not None:
            return exit_from(lat_deg, lon_deg, course_deg, rest)
        return past_exit(lat_deg, lon_deg, rest)
    return [*rejoin(lat_deg, lon_deg, prev, rest[0]), *rest]


def past_exit(lat_deg: float, lon_deg: float, rest: Sequence[P]) -> list[P]:
    """``rest`` starting with a loiter's modelled exit (points of the next item, the last on
    the line to that item's position) for a plane already past that exit along the line (a
    plan filed again by a restarted serve while it flew on: the soak's ArduPlane, 700 m past
    it, was filed flying back to it, UAS_OUT_OV): the exit left out, back onto the line
    (:func:`rejoin`); ``rest`` as it is before the exit's end."""
    run = next((k for k, q in enumerate(rest) if q.explicit), len(rest))
    if run == 0 or run == len(rest):
        return list(rest)
    on_line, nxt = rest[run - 1], rest[run]
    k = math.cos(math.radians(on_line.lat_deg))
    le = (nxt.lon_deg - on_line.lon_deg) * _M_PER_DEG_LON * k
    ln = (nxt.lat_deg - on_line.lat_deg) * _M_PER_DEG_LAT
    pe = (lon_deg - on_line.lon_deg) * _M_PER_DEG_LON * k
    pn = (lat_deg - on_line.lat_deg) * _M_PER_DEG_LAT
    if pe * le + pn * ln <= 0.0:
        return list(rest)
    return [*rejoin(lat_deg, lon_deg, on_line, nxt), *rest[run:]]


def exit_from(lat_deg: float, lon_deg: float, course_deg: float, rest: Sequence[P]) -> list[P]:
    """A PX4 plane out of its loiter at ``lat_deg, lon_deg`` flying ``course_deg``: ``rest``
    starts with the modelled exit (points of the next item, the last on the line from the
    loiter's centre to that item's position, which follows); it turns from its course onto
    that line, pursuing the line's point one guidance distance past its projection
    (:func:`.fixed_wing_loiter._px4_exit`), then goes on along it. ``rest`` as it is when
    there is no such line or the plane is past its end."""
    run = next((k for k, q in enumerate(rest) if q.explicit), len(rest))
    if run == 0 or run == len(rest):
        return list(rest)
    on_line, nxt = rest[run - 1], rest[run]
    k = math.cos(math.radians(on_line.lat_deg))
    le = (nxt.lon_deg - on_line.lon_deg) * _M_PER_DEG_LON * k
    ln = (nxt.lat_deg - on_line.lat_deg) * _M_PER_DEG_LAT
    length = math.hypot(le, ln)
    if length < 1.0:
        return list(rest)
    ue, un = le / length, ln / length
    pe = (lon_deg - on_line.lon_deg) * _M_PER_DEG_LON * k
    pn = (lat_deg - on_line.lat_deg) * _M_PER_DEG_LAT
    speed = min(max(nxt.speed_mps, 1.0), PX4_TRIM_MPS)
    s = pe * ue + pn * un + L1_DAMPING * PX4_PERIOD_S * speed / math.pi
    if s >= length - 1.0:
        return list(rest[run:])
    alt = on_line.alt_amsl_m + (nxt.alt_amsl_m - on_line.alt_amsl_m) * max(s, 0.0) / length
    lat = on_line.lat_deg + un * s / _M_PER_DEG_LAT
    lon = on_line.lon_deg + ue * s / (_M_PER_DEG_LON * k)
    target = nxt.moved(lat, lon, alt).synthetic()
    here = nxt.moved(lat_deg, lon_deg, alt).synthetic()
    turn = takeoff_turn(here, course_deg, target, speed, period_s=PX4_PERIOD_S, roll_in_s=0.0,
                        roll_limit_deg=PX4_ROLL_LIMIT_DEG, full_bank=True)  # fmt: skip
    return [*turn, target, *rest[run:]]
