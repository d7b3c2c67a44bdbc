"""A fixed wing's mission as the autopilot flies it, as the points of its 4D plan
(docs/autopilots.md, "Fixed wings: take-off, loiters, landing"). Pure.

A multirotor flies a mission's items as points: it climbs on the spot at NAV_TAKEOFF and
hovers at a loiter. A fixed wing cannot:
- **NAV_TAKEOFF** (no position of its own: "here") is a climb-out from where the vehicle
  stands along the take-off heading, the heading to the next waypoint, to the take-off
  altitude: the climb ends ``height / tan(pitch)`` ahead with the item's minimum pitch
  (param1), else at :data:`TAKEOFF_CLIMB_RATE_MPS` at the take-off (minimum) airspeed,
  ``height * 0.7 * speed / 5`` (at most at the next waypoint), not above home; the first
  :data:`ROLL_FRACTION` of that run is the ground roll (a point on the ground, "no position
  of its own"). ArduPlane and PX4 (runway take-off) both climb straight out and turn only
  after it (measured on ArduPlane 4.6 SITL, param1 15 deg, 30 m: lift-off about 40 m out,
  30 m reached 111 m out, where 30 / tan(15 deg) = 112 m; a straight line from the start
  put the rolling plane 10.3 m below it, outside its flight geometry).
  From the climb's end along a heading that is not the next waypoint's, ArduPlane turns
  towards it on its L1 pursuit from where it is (:mod:`.fixed_wing_turn`).
- **NAV_TAKEOFF with a position** (PX4: its runway take-off heads for it) is the same
  climb-out from the vehicle's home towards that position, then level to it; a position
  within :data:`HERE_M` of where it starts (QGroundControl gives a plane's take-off the
  launch position) is "here". PX4 v1.15.2
  SIH keeps no pitch in the item (read back without it): lift-off about 18 m out, 30 m
  reached 95-99 m out (the model: 32 and 92 m at 22 m/s filed), 5 m above it after, then
  level; a straight line from home to a take-off position 250 m out put it 18-28 m above
  its plan.
- **NAV_LOITER_TO_ALT** (31) is a circle around its position flown until the altitude is
  reached at the climb (descent) rate; **NAV_LOITER_TURNS** (18) that many turns at the
  item's altitude; **NAV_LOITER_TIME** (19) a circle for that long: entered on the plane's
  turn, left on the tangent to the next waypoint, then back on the line from the centre
  (:mod:`.fixed_wing_loiter`).
- a **landing sequence** (DO_LAND_START, its approach waypoints, NAV_LAND) is already a
  descent along the track: its points are kept as they are (PX4 v1.15 SIH glides from the
  approach waypoint straight to the landing point, within 3 m of that line, and touches down
  about 45 m past the landing point, stopping about 55 m past it); PX4 leaves a
  NAV_LOITER_TO_ALT before NAV_LAND at the circle's point towards the landing point
  (:mod:`.fixed_wing_landing`).
Every point made from an item keeps the item's mission seq (the plan from the current item
on includes the whole of a circle being flown; the point back on the track after a loiter
has the next item's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeVar

from gcs_utm.envelope import FIXED_WING_MIN_SPEED_FACTOR
from gcs_utm.services.fixed_wing_landing import landing_exit
from gcs_utm.services.fixed_wing_loiter import STEP_RAD, loiter_points
from gcs_utm.services.fixed_wing_point import (
    LOITER_COMMANDS,
    NAV_LAND,
    NAV_LOITER_TO_ALT,
    NAV_TAKEOFF,
    Point,
)
from gcs_utm.services.fixed_wing_runway import px4_takeoff, runway_from_heading
from gcs_utm.services.fixed_wing_turn import takeoff_turn

TAKEOFF_CLIMB_RATE_MPS = 5.0
"""A take-off without a pitch climbs at the autopilot's maximum climb rate: ArduPlane
TECS_CLMB_MAX and PX4 FW_T_CLMB_MAX default to 5 m/s."""
ROLL_FRACTION = 0.35
"""The part of the take-off run on the ground (ArduPlane 4.6 SITL: 40 of 111 m)."""
HERE_M = 10.0
"""A take-off position this close to where the vehicle starts gives no heading: "here" (the
launch position a ground station wrote, GNSS noise, a home rounded to 1e-4 deg)."""
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


P = TypeVar("P", bound=Point)


def _offset(p: Point, east_m: float, north_m: float) -> tuple[float, float]:
    k = math.cos(math.radians(p.lat_deg))
    return (
        p.lat_deg + north_m / _M_PER_DEG_LAT,
        p.lon_deg + east_m / (_M_PER_DEG_LON * k),
    )


def _east_north(a: Point, b: Point) -> tuple[float, float]:
    """b relative to a, metres east and north (flat earth: mission legs are short)."""
    k = math.cos(math.radians(a.lat_deg))
    return (b.lon_deg - a.lon_deg) * _M_PER_DEG_LON * k, (b.lat_deg - a.lat_deg) * _M_PER_DEG_LAT


def fixed_wing_points(
    points: Sequence[P],
    *,
    ground_alt_m: float | None,
    climb_rate_mps: float,
    descent_rate_mps: float,
    loiter_radius_m: float,
    home_deg: tuple[float, float] | None = None,
    loiter_landing: bool = False,
    takeoff_heading_deg: float | None = None,
    heads_for_takeoff_position: bool = True,
    turn_after_takeoff: bool = False,
    loiter_exit_on_goal: bool = False,
) -> list[P]:
    """``points`` (mission order, AMSL) as a fixed wing flies them (module docstring).
    ``ground_alt_m``: where a take-off starts (the vehicle's home; None: the point before);
    ``home_deg`` (lat, lon): where a take-off with a position of its own starts when no point
    is before it (PX4); ``loiter_landing`` (PX4): a NAV_LAND after a NAV_LOITER_TO_ALT is
    approached from the circle's point towards it (:mod:`.fixed_wing_landing`);
    ``takeoff_heading_deg``: the vehicle's heading when it armed (a take-off without a
    position climbs out along it; None: towards the next waypoint);
    ``heads_for_takeoff_position`` False: the autopilot ignores a take-off's position
    (ArduPlane's ``do_takeoff``); ``turn_after_takeoff`` (ArduPlane): from the climb's end
    along ``takeoff_heading_deg`` it turns towards the next waypoint as it flies it
    (:mod:`.fixed_wing_turn`); ``loiter_exit_on_goal`` (PX4): a loiter is left as soon as its
    goal is met (:mod:`.fixed_wing_loiter`)."""
    out: list[P] = []
    for i, p in enumerate(points):
        before = out[-1] if out else None
        if p.command == NAV_TAKEOFF and (
            not heads_for_takeoff_position or _here(p, before, home_deg)
        ):
            here = _from_start(p, before, home_deg)
            after = points[i + 1 :]
            climb = _climb_out(here, before, after, ground_alt_m, takeoff_heading_deg)
            out.extend(climb)
            nxt = next((q for q in after if q.explicit), None)
            if turn_after_takeoff and takeoff_heading_deg is not None and len(climb) == 2 and nxt:
                out.extend(takeoff_turn(climb[-1], takeoff_heading_deg, nxt, nxt.speed_mps))
        elif p.command == NAV_TAKEOFF:
            nxt = next((q for q in points[i + 1 :] if q.explicit), None)
            heading = takeoff_heading_deg
            out.extend(_climb_out_to(p, before, home_deg, ground_alt_m, heading, nxt=nxt))
        elif p.command in LOITER_COMMANDS and out:
            rate = climb_rate_mps if p.alt_amsl_m >= out[-1].alt_amsl_m else descent_rate_mps
            # PX4 leaves a landing's loiter towards the landing point (:func:`_landing_exit`),
            # not on the tangent to the next item
            to_land = loiter_landing and points[i + 1 : i + 2] and points[i + 1].command == NAV_LAND
            after = [] if to_land else points[i + 1 :]
            out.extend(
                loiter_points(
                    p, out[-1], after, rate, loiter_radius_m, leaves_on_goal=loiter_exit_on_goal
                )
            )
        elif loiter_landing and p.command == NAV_LAND and i and out:
            out = _descended_before(out, points[i - 1])
            out.extend(_landing_exit(points[i - 1], out[-1], p, loiter_radius_m))
            out.append(p)
        else:
            out.append(p)
    return out


def _descended_before(out: list[P], loiter: Point) -> list[P]:
    """A landing's NAV_LOITER_TO_ALT modelled as at most a turn is reached at its altitude:
    PX4 descends (climbs) on the way to it and makes NAV_LAND current where it meets the
    circle (measured on PX4 v1.15.2 SIH, 40 -> 30 m: at the loiter's altitude 10 m before
    the circle, NAV_LAND current there); the circle is then its entry point, at the loiter's
    altitude, and the landing's path goes round from there (:func:`_landing_exit`)."""
    if loiter.command != NAV_LOITER_TO_ALT:
        return out
    start = len(out)
    while start > 0 and out[start - 1].seq == loiter.seq:
        start -= 1
    circle = out[start:]
    if not circle or len(circle) > 2 + round(2.0 * math.pi / STEP_RAD):
        return out  # more than a turn: it orbits down (up) first
    entry = circle[0]
    return [*out[:start], entry.moved(entry.lat_deg, entry.lon_deg, loiter.alt_amsl_m)]


def _landing_exit(loiter: Point, last: Point, land: P, default_radius_m: float) -> list[P]:
    """The rest of a NAV_LOITER_TO_ALT's circle to its point towards the landing point, at
    the loiter's altitude, when ``loiter`` is the landing's approach: modelled points of the
    landing item (PX4 makes NAV_LAND current once the loiter's altitude is reached, and flies
    them as part of it: a plan from NAV_LAND on starts with them)."""
    if loiter.command != NAV_LOITER_TO_ALT or not land.explicit:
        return []
    radius = loiter.radius_m if loiter.radius_m != 0.0 else default_radius_m
    exits = landing_exit(
        (loiter.lat_deg, loiter.lon_deg),
        radius,
        (last.lat_deg, last.lon_deg),
        (land.lat_deg, land.lon_deg),
    )
    return [land.moved(lat, lon, last.alt_amsl_m).synthetic() for lat, lon in exits]


def _here(p: Point, before: Point | None, home_deg: tuple[float, float] | None) -> bool:
    """Whether a take-off is "here": no position of its own, or the position the vehicle
    starts from (QGroundControl gives a plane's NAV_TAKEOFF the launch position; ArduPlane
    climbs out along its heading whatever the item's position, and a runway take-off towards
    a point within :data:`HERE_M` of where it stands has no heading either)."""
    if not p.explicit:
        return True
    start = (before.lat_deg, before.lon_deg) if before is not None else home_deg
    if start is None:
        return False
    k = math.cos(math.radians(p.lat_deg))
    east_m = (p.lon_deg - start[1]) * _M_PER_DEG_LON * k
    north_m = (p.lat_deg - start[0]) * _M_PER_DEG_LAT
    return math.hypot(east_m, north_m) < HERE_M


def _from_start(p: P, before: Point | None, home_deg: tuple[float, float] | None) -> P:
    """A take-off that is "here" with a position of its own (or whose position the autopilot
    ignores), moved to where the vehicle starts (a modelled point); one without a position
    as it is."""
    if not p.explicit:
        return p
    start = (before.lat_deg, before.lon_deg) if before is not None else home_deg
    if start is None:  # not reached: _here needs a start for a take-off with a position
        return p
    return p.moved(start[0], start[1], p.alt_amsl_m).synthetic()


def _climb_out_to(
    p: P,
    before: P | None,
    home_deg: tuple[float, float] | None,
    ground_alt_m: float | None,
    heading_deg: float | None = None,
    *,
    nxt: P | None = None,
) -> list[P]:
    """A take-off with a position of its own (PX4: the runway take-off heads for it): the
    climb-out from where the vehicle stands (the point before, else home) towards it; from a
    parked ``heading_deg`` that is not towards it, the ground roll along that heading and the
    turn back onto the line; then the pursuit of ``nxt`` (the next waypoint) from where the
    take-off altitude is reached, or without ``nxt`` level to the take-off's position
    (:func:`.fixed_wing_runway.px4_takeoff`)."""
    start_deg = (before.lat_deg, before.lon_deg) if before is not None else home_deg
    if start_deg is None:
        return [p]
    start = p.moved(start_deg[0], start_deg[1], p.alt_amsl_m).synthetic()
    climb = _climb_out(start, before, [p], ground_alt_m)
    if len(climb) < 2:  # no climb to model
        return [p]
    if nxt is not None:
        return px4_takeoff(start, heading_deg, climb, p, nxt)
    turned = None if heading_deg is None else runway_from_heading(start, heading_deg, climb, p)
    if turned is not None:
        return turned
    ends = [q.synthetic() for q in climb if math.hypot(*_east_north(q, p)) >= 1.0]
    return [*ends, p]


def _climb_out(
    p: P,
    before: Point | None,
    after: Sequence[Point],
    ground_alt_m: float | None,
    heading_deg: float | None = None,
) -> list[P]:
    """The ground roll's end and the end of the take-off climb: along ``heading_deg`` (the
    vehicle's, when it armed), else along the heading to the next waypoint with a position of
    its own; where it is (a vertical climb) without either."""
    nxt = next((q for q in after if q.explicit), None)
    base = before.alt_amsl_m if before is not None else ground_alt_m
    if base is None or p.alt_amsl_m - base <= 0.0:
        return [p]
    height_m = p.alt_amsl_m - base
    if heading_deg is not None:
        east, north = math.sin(math.radians(heading_deg)), math.cos(math.radians(heading_deg))
        to_next_m = math.inf
    elif nxt is None:
        return [p]
    else:
        east, north = _east_north(p, nxt)
        to_next_m = math.hypot(east, north)
        if to_next_m < 1.0:
            return [p]
    if 1.0 <= p.amount < 89.0:  # the take-off's minimum pitch, degrees
        run_m = height_m / math.tan(math.radians(p.amount))
    else:
        # at the autopilot's maximum climb rate and its take-off (lowest) airspeed
        run_m = height_m * FIXED_WING_MIN_SPEED_FACTOR * max(p.speed_mps, 0.1)
        run_m /= TAKEOFF_CLIMB_RATE_MPS
    run_m = min(to_next_m, run_m)
    roll_m = ROLL_FRACTION * run_m
    unit = math.hypot(east, north)
    ux, uy = east / unit, north / unit
    lat_r, lon_r = _offset(p, ux * roll_m, uy * roll_m)
    lat, lon = _offset(p, ux * run_m, uy * run_m)
    return [p.moved(lat_r, lon_r, base).synthetic(), p.moved(lat, lon, p.alt_amsl_m)]
