"""A fixed wing's loiter item as the points it flies (docs/autopilots.md, "Fixed wings"). Pure.

Used by :mod:`.fixed_wing_plan` for NAV_LOITER_TURNS, NAV_LOITER_TIME and NAV_LOITER_TO_ALT.
As ArduPlane flies them (ArduPlane ``commands_logic.cpp``, ``navigation.cpp``; PX4's
fixed-wing loiters alike):

- **Radius**: the item's, else the vehicle's default loiter radius (ArduPlane WP_LOITER_RAD,
  PX4 NAV_LOITER_RAD). A radius of 1 m or less is no radius: ArduPlane's ``update_loiter``
  takes WP_LOITER_RAD for it, and ArduPilot reads a NAV_LOITER_TIME back with param3 = +1 or
  -1, the direction only (the soak's ArduPlane was filed circling a 1 m circle). The sign
  gives the direction: clockwise unless negative.
- **Entry on the turn**: the plane flies at the centre until about 1.4 radii from it
  (:data:`CAPTURE_RADII`), then the L1 controller turns it onto the circle, which it joins
  on the tangent in its turn direction, not at the point nearest the previous one: arriving
  from the east on a clockwise circle it joins the southern side, heading west (measured on
  ArduPlane 4.6 SITL: on the line to the centre until 115-150 m from it, on an 80 m circle
  55-90 degrees round).
- **The goal** (the turns, the time, the altitude) is counted from there. A loiter to an
  altitude changes it on the way (ArduPlane's glide slope to the loiter point, or its climb
  first) as far as the climb or descent rate allows at its speed, and the rest on the
  circle. Then the plane **goes on round the circle until it heads for the next
  waypoint** (``verify_loiter_heading``) and leaves on the tangent towards it.
- **Exit track**: with the item's param4 0 (the default) the next leg is tracked from the
  loiter's centre (ArduPlane ``loiter_xtrack``, PX4 ``loiter_exit_xtrack``): the plane
  runs on along its tangent for about half a radius, then converges on the line from the
  centre to the next waypoint, within about two radii of the exit (measured: 155-210 m
  after leaving an 80 m circle at 22 m/s, NAVL1_PERIOD 15); a point on the tangent and a
  point on that line model it. With param4 1 it flies straight from where it left.
Circle points are every 22.5 degrees (a chord is at most 2 % of the radius inside the arc).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeVar

from gcs_utm.services.fixed_wing_point import (
    LOITER_COMMANDS as LOITERS,
)
from gcs_utm.services.fixed_wing_point import (
    NAV_LOITER_TIME,
    NAV_LOITER_TO_ALT,
    NAV_TAKEOFF,
    Point,
)
from gcs_utm.services.fixed_wing_turn import (
    L1_DAMPING,
    PX4_PERIOD_S,
    PX4_ROLL_LIMIT_DEG,
    PX4_TRIM_MPS,
    takeoff_turn,
)

P = TypeVar("P", bound=Point)

NO_RADIUS_M = 1.0
"""A loiter radius this small or smaller is the vehicle's default (ArduPlane update_loiter)."""
JOIN_RADII = 2.0
"""After a loiter the plane is on the line from the centre to the next waypoint this many
radii further along it than where it left the circle."""
CAPTURE_RADII = 1.4
"""Heading for a loiter, the plane flies at its centre until this many radii from it, then
turns onto the circle: ArduPlane's L1 switches from capture to circle when the radial error
nears ``v Kv / Kx``, its L1 distance (79 m at 22 m/s, NAVL1_PERIOD 15), about a radius
(measured: it left the line 115-150 m from the centre of an 80 m circle and joined it on the
tangent from there). The latest of those: a plane turning earlier cuts the corner on the
inside, which the fixed-wing band takes as on its plan; one turning later would overshoot."""
EXIT_RUN_RADII = 0.5
"""Leaving a loiter, the plane flies on along its tangent this many radii before it turns
onto the line from the centre (measured: 35-40 m on an 80 m circle)."""
SAME_M = 0.5  # a point this close to the circle's entry is the entry
STEP_RAD = math.pi / 8.0
MAX_TURNS = 20.0  # a circle is modelled up to this many turns (a bound on points)
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


def _en(centre: Point, q: Point) -> tuple[float, float]:
    """q relative to centre, metres east and north (flat earth: a loiter is small)."""
    k = math.cos(math.radians(centre.lat_deg))
    return (
        (q.lon_deg - centre.lon_deg) * _M_PER_DEG_LON * k,
        (q.lat_deg - centre.lat_deg) * _M_PER_DEG_LAT,
    )


def _at(centre: P, east_m: float, north_m: float, alt_amsl_m: float, like: P) -> P:
    k = math.cos(math.radians(centre.lat_deg))
    lat = centre.lat_deg + north_m / _M_PER_DEG_LAT
    lon = centre.lon_deg + east_m / (_M_PER_DEG_LON * k)
    return like.moved(lat, lon, alt_amsl_m)


def radius_m(p: Point, default_radius_m: float) -> float:
    """The signed radius flown (> 0 clockwise): the item's, else the default with its sign."""
    if abs(p.radius_m) <= NO_RADIUS_M:
        return -default_radius_m if p.radius_m < 0.0 else default_radius_m
    return p.radius_m


def _tangent_angle(east_m: float, north_m: float, r: float, sense: float, leaving: bool) -> float:
    """The angle (from east) of the circle's point where a plane turning ``sense`` (-1
    clockwise) joins it coming from (``leaving``: leaves it heading for) the point
    ``east_m, north_m`` off the centre; the nearest point when that is inside the circle."""
    phi = math.atan2(north_m, east_m)
    d = math.hypot(east_m, north_m)
    if d <= r:
        return phi
    half = math.acos(r / d)
    return phi - sense * half if leaving else phi + sense * half


def loiter_points(
    p: P,
    before: Point,
    after: Sequence[P],
    rate_mps: float,
    default_radius_m: float,
    *,
    leaves_on_goal: bool = False,
) -> list[P]:
    """The loiter item ``p`` flown after ``before``, ``after`` the points that follow it: its
    circle from the entry to the exit, then (exit track from the centre) the point where the
    plane is back on the line to the next waypoint (module docstring). ``leaves_on_goal``
    (PX4): it leaves the circle as soon as the goal is met and turns onto the line from the
    centre (:func:`_px4_exit`)."""
    radius = radius_m(p, default_radius_m)
    r = abs(radius)
    if r < NO_RADIUS_M:
        return [p]
    sense = -1.0 if radius > 0.0 else 1.0  # clockwise: the angle (from east) decreases
    capture = _capture(p, before, r)
    start = _tangent_angle(*_en(p, capture or before), r, sense, leaving=False)
    z0, turns = _goal(p, before, (r * math.cos(start), r * math.sin(start)), r, rate_mps)
    goal_rad = min(turns, MAX_TURNS) * 2.0 * math.pi
    nxt = next((q for q in after if q.explicit), None)
    sweep = goal_rad
    px4_exit = leaves_on_goal and not p.exit_xtrack
    if leaves_on_goal and p.command == NAV_LOITER_TIME:
        sweep = goal_rad = _px4_time_rad(p, capture, start, r)
    if nxt is not None and math.hypot(*_en(p, nxt)) > r and not px4_exit:
        exit_a = _tangent_angle(*_en(p, nxt), r, sense, leaving=True)
        sweep += ((exit_a - (start + sense * goal_rad)) * sense) % (2.0 * math.pi)
    steps = max(1, math.ceil(sweep / STEP_RAD - 1e-9))
    out: list[P] = [] if capture is None else [capture]
    for k in range(int(_is_entry(p, before, start, r, z0)), steps + 1):
        swept = min(k * STEP_RAD, sweep)
        a = start + sense * swept
        frac = min(swept / goal_rad, 1.0) if goal_rad > 0.0 else 1.0
        alt = z0 + (p.alt_amsl_m - z0) * frac
        out.append(_at(p, r * math.cos(a), r * math.sin(a), alt, p))
    if nxt is not None and nxt is after[0] and nxt.command not in LOITERS | {NAV_TAKEOFF}:
        exit_a = start + sense * sweep
        out.extend(
            _px4_exit(p, out[-1], exit_a, sense, nxt) if px4_exit else _join(p, out[-1], nxt, r)
        )
    return out


def _is_entry(p: Point, before: Point, start: float, r: float, alt_amsl_m: float) -> bool:
    """Whether ``before`` is the circle's entry point (``start`` round the centre, within
    :data:`SAME_M`, at the entry's altitude): a mission whose waypoint before the loiter is
    on its circle (an upload that keeps a loiter: adapters/mavlink/loiter_kept.py) starts the
    circle there, once."""
    be, bn = _en(p, before)
    off_m = math.hypot(be - r * math.cos(start), bn - r * math.sin(start))
    return off_m <= SAME_M and abs(before.alt_amsl_m - alt_amsl_m) <= SAME_M


def _px4_time_rad(p: P, capture: P | None, start: float, r: float) -> float:
    """The angle a PX4 plane flies round its NAV_LOITER_TIME circle: the time counts from
    where it is within the circle's acceptance (the capture, before it joins the circle on
    its tangent) and it flies its trim airspeed (``PX4_TRIM_MPS``), not the plan's speed.
    Measured on PX4 v1.15.2 SIH (14.5 m/s, 80 m, 20 s): 155 deg round from its entry, where
    20 s at the plan's 22 m/s from the join made 315 deg."""
    speed = min(max(p.speed_mps, 0.1), PX4_TRIM_MPS)
    lead_s = 0.0
    if capture is not None:
        ce, cn = _en(p, capture)
        lead_s = math.hypot(ce - r * math.cos(start), cn - r * math.sin(start)) / speed
    return max(p.amount - lead_s, 0.0) * speed / r


def _px4_exit(p: P, left: P, at_rad: float, sense: float, nxt: P) -> list[P]:
    """A PX4 plane leaving its loiter at ``left`` (``at_rad`` round the centre, turning
    ``sense``) once the goal is met (MissionBlock: the loiter item completes when its time is
    up; without param4 > 0 no tangent exit): it tracks the line from the centre to ``nxt``
    (the previous setpoint is the loiter's), turning on from the circle's tangent onto it. As
    the pursuit of the line's point one guidance distance past ``left``'s projection (NPFG
    period 10 s, PX4's default; roll limit 50 deg, FW_R_LIM): measured on PX4 v1.15.2 SIH
    (14.5 m/s, 80 m circle, leaving on its north-west side for a waypoint to the south) within
    5.4 m of the plane, which the ArduPlane exit (on round to the tangent towards the next
    waypoint, 150 deg further) put 19 m off (UAS_IN_CV)."""
    ne, nn = _en(p, nxt)
    length = math.hypot(ne, nn)
    if length <= 0.0:
        return []
    ue, un = ne / length, nn / length
    le, ln = _en(p, left)
    speed = min(max(nxt.speed_mps, 1.0), PX4_TRIM_MPS)
    s = le * ue + ln * un + L1_DAMPING * PX4_PERIOD_S * speed / math.pi
    if s >= length:
        return []
    alt = p.alt_amsl_m + (nxt.alt_amsl_m - p.alt_amsl_m) * s / length
    target = _at(p, ue * s, un * s, alt, nxt).synthetic()
    # the course on the circle: its tangent in the turn's sense
    course = math.degrees(math.atan2(-sense * math.sin(at_rad), sense * math.cos(at_rad)))
    turn = takeoff_turn(left, course, target, speed, period_s=PX4_PERIOD_S, roll_in_s=0.0,
                        roll_limit_deg=PX4_ROLL_LIMIT_DEG, full_bank=True)  # fmt: skip
    return [*turn, target]


def _capture(p: P, before: Point, r: float) -> P | None:
    """Where the plane heading for the loiter's centre turns onto the circle:
    :data:`CAPTURE_RADII` radii from the centre on the line from ``before`` (None when
    ``before`` is nearer). A modelled point of the loiter's item, at the altitude there."""
    be, bn = _en(p, before)
    d = math.hypot(be, bn)
    if d <= CAPTURE_RADII * r:
        return None
    k = CAPTURE_RADII * r / d
    alt = before.alt_amsl_m
    if p.command == NAV_LOITER_TO_ALT:  # it descends (climbs) on the way: not above either
        alt = p.alt_amsl_m + (before.alt_amsl_m - p.alt_amsl_m) * k
    return _at(p, be * k, bn * k, alt, p).synthetic()


def _goal(
    p: Point, before: Point, entry_m: tuple[float, float], r: float, rate_mps: float
) -> tuple[float, float]:
    """The altitude at the circle's entry (``entry_m`` east, north of the centre) and the
    turns of the goal on a circle of radius ``r`` (module docstring)."""
    turn_s = 2.0 * math.pi * r / max(p.speed_mps, 0.1)
    if p.command == NAV_LOITER_TIME:
        return p.alt_amsl_m, max(p.amount, 0.0) / turn_s
    if p.command != NAV_LOITER_TO_ALT:
        return p.alt_amsl_m, max(p.amount, 0.0)
    # on the way as far as the rate allows at its speed, the rest on the circle
    be, bn = _en(p, before)
    leg_m = math.hypot(be - entry_m[0], bn - entry_m[1])
    dz = p.alt_amsl_m - before.alt_amsl_m
    reach_m = leg_m * max(rate_mps, 0.1) / max(p.speed_mps, 0.1)
    z0 = before.alt_amsl_m + math.copysign(min(abs(dz), reach_m), dz)
    return z0, abs(p.alt_amsl_m - z0) / max(rate_mps, 0.1) / turn_s


def _join(p: P, left: P, nxt: P, r: float) -> list[P]:
    """The point on the line from the loiter's centre to ``nxt`` where the plane that left
    the circle at ``left`` is back on it (none with param4 1, or a leg too short)."""
    if p.exit_xtrack:
        return []
    ne, nn = _en(p, nxt)
    length = math.hypot(ne, nn)
    if length <= 0.0:
        return []
    ue, un = ne / length, nn / length
    le, ln = _en(p, left)
    s = le * ue + ln * un + JOIN_RADII * r
    if s >= length - r:
        return []
    alt = p.alt_amsl_m + (nxt.alt_amsl_m - p.alt_amsl_m) * s / length
    # on along the tangent (towards the next waypoint) first
    te, tn = ne - le, nn - ln
    run = EXIT_RUN_RADII * r / max(math.hypot(te, tn), 1e-9)
    return [
        _at(p, le + te * run, ln + tn * run, left.alt_amsl_m, nxt).synthetic(),
        _at(p, ue * s, un * s, alt, nxt).synthetic(),
    ]
