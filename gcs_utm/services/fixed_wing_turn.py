"""ArduPlane's turn from its take-off course to the next waypoint (pure; docs/autopilots.md,
"Fixed wings: take-off, loiters, landing").

ArduPlane holds the course it rolled on until the take-off altitude is reached
(``verify_takeoff``); then it sets ``prev_WP_loc = next_WP_loc = current_loc`` and clears
``next_wp_crosstrack`` ("don't cross-track on completion of takeoff, as otherwise we can end
up doing too sharp a turn"), so the next waypoint is flown from where the plane is at each
instant (``update_waypoint(current_loc, next)``): a pursuit by its L1 controller, not the
line from the climb's end. The L1 lateral acceleration ``2 V^2 / L1 sin(eta)`` (``eta`` the
angle between the course and the bearing to the waypoint, ``L1 = damping * period * V / pi``)
is capped by the roll limit; so the plane runs on for a moment along its take-off course
(the take-off's end, the roll-in), turns on a widening arc and reaches the bearing to the
waypoint ``L1 eta / 2`` to the outside of the line from the climb's end: a straight line
from there put the soak's ArduPlane (take-off course north-east, next waypoint north) 45-50 m
outside its plan (UAS_IN_CV, then UAS_OUT_OV and a back_to_plan). Measured on ArduPlane 4.6
SITL (22 m/s, NAVL1_PERIOD 15): the path of this model with a 1.4 s roll-in is within 2.5 m
of the plane's through the 45 deg turn (``tests/data/flown/arduplane_takeoff_turn.json``).
"""

from __future__ import annotations

import math
from typing import TypeVar

from gcs_utm.services.fixed_wing_point import Point

P = TypeVar("P", bound=Point)

L1_PERIOD_S = 15.0
"""ArduPlane NAVL1_PERIOD (15 in its SITL defaults, 17 by default; a longer period turns
wider)."""
L1_DAMPING = 0.75
"""ArduPlane NAVL1_DAMPING (default)."""
ROLL_LIMIT_DEG = 45.0
"""ArduPlane ROLL_LIMIT_DEG (default 45; 65 in its SITL defaults): caps the turn."""
PX4_PERIOD_S = 10.0
"""PX4's NPFG_PERIOD (default): its guidance period, for the same pursuit out of a loiter."""
PX4_ROLL_LIMIT_DEG = 50.0
"""PX4's FW_R_LIM (default)."""
PX4_TRIM_MPS = 15.0
"""PX4's FW_AIRSPD_TRIM (default): the airspeed of its turns, whatever speed a plan is timed
at (the soak's PX4 SIH plane flew 14.5 m/s; its plans are filed at 22 m/s)."""
ROLL_IN_S = 1.4
"""From the take-off altitude to the turn (the check, the roll-in), fitted to the track."""
STEP_M = 2.0  # integration step
POINT_EVERY_RAD = math.radians(15.0)  # a modelled point every 15 deg of heading
DONE_RAD = math.radians(8.0)
"""Within this of the bearing to the waypoint the turn is over: the rest is the straight line
to it (within 3 m of the pursuit), from where ArduPlane climbing first may climb (the
fixed-wing band allows it from a leg's start; it climbed 11 m in the last 30 m of its turn)."""
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def takeoff_turn(
    end: Point,
    course_deg: float,
    nxt: P,
    speed_mps: float,
    *,
    period_s: float = L1_PERIOD_S,
    roll_in_s: float = ROLL_IN_S,
    roll_limit_deg: float = ROLL_LIMIT_DEG,
    full_bank: bool = False,
) -> list[P]:
    """The plane's path from the take-off's end ``end`` (at the take-off altitude, flying
    ``course_deg``) until it heads for ``nxt``: modelled points of ``nxt`` (the item current
    then), at the altitudes of the straight line from ``end`` to ``nxt``; [] when it already
    heads for it (module docstring). ``full_bank``: the turn is made at the roll limit until
    the plane heads for ``nxt`` (PX4's turn out of a loiter, :mod:`.fixed_wing_loiter`: its
    guidance saturates, where L1's pursuit eases off as the bearing error closes)."""
    k = math.cos(math.radians(end.lat_deg))
    goal_e = (nxt.lon_deg - end.lon_deg) * _M_PER_DEG_LON * k
    goal_n = (nxt.lat_deg - end.lat_deg) * _M_PER_DEG_LAT
    total_m = math.hypot(goal_e, goal_n)
    psi = math.radians(course_deg)  # course, clockwise from north
    if total_m < 1.0 or abs(_wrap(psi - math.atan2(goal_e, goal_n))) < DONE_RAD:
        return []
    speed = max(speed_mps, 1.0)
    l1_m = L1_DAMPING * period_s * speed / math.pi
    max_rate = 9.81 * math.tan(math.radians(roll_limit_deg)) / speed**2  # rad per m
    e = n = 0.0
    run_m = roll_in_s * speed
    flown = 0.0
    out: list[P] = []
    last_psi = psi
    emitted_at = 0.0  # (not at the start: that point is the caller's)

    def emit() -> None:
        nonlocal emitted_at
        if flown - emitted_at < 1.0:
            return  # a point there already
        emitted_at = flown
        left = math.hypot(goal_e - e, goal_n - n)
        frac = min(max(1.0 - left / total_m, 0.0), 1.0)
        alt = end.alt_amsl_m + (nxt.alt_amsl_m - end.alt_amsl_m) * frac
        lat = end.lat_deg + n / _M_PER_DEG_LAT
        lon = end.lon_deg + e / (_M_PER_DEG_LON * k)
        out.append(nxt.moved(lat, lon, alt).synthetic())

    while flown < 20.0 * l1_m:  # bound: an L1 turn settles within a few L1 distances
        left = math.hypot(goal_e - e, goal_n - n)
        eta = _wrap(psi - math.atan2(goal_e - e, goal_n - n))
        if left < l1_m or (flown >= run_m and abs(eta) < DONE_RAD):
            break
        if flown >= run_m:
            if flown - STEP_M < run_m:
                emit()  # where the turn starts
            rate = max_rate if full_bank else min(2.0 * math.sin(abs(eta)) / l1_m, max_rate)
            psi -= math.copysign(rate * STEP_M, eta)
        e += math.sin(psi) * STEP_M
        n += math.cos(psi) * STEP_M
        flown += STEP_M
        if abs(_wrap(psi - last_psi)) >= POINT_EVERY_RAD:
            last_psi = psi
            emit()
    emit()
    return out
