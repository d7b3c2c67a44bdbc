"""A plan uploaded to an ArduPlane keeps the pilot's loiters as loiter items (pure;
docs/autopilots.md, "Loiters kept").

The plan filed from a fixed wing's mission models a NAV_LOITER_TURNS / NAV_LOITER_TIME /
NAV_LOITER_UNLIM as points on its circle, every 22.5 degrees
(:mod:`gcs_utm.services.fixed_wing_loiter`). A plan derived from it (back_to_plan, a re-plan)
holds those points; sent as NAV_WAYPOINTs they are no loiter: ArduPlane accepts each
WP_RADIUS (50 m) before it and turns round it, so it flies a wider, ragged ring than the
filed circle (and conformance may fire). So :func:`keep_loiters` replaces a run of the
encoded mission's waypoints that lie on a loiter's circle (at the loiter's altitude, all at
the same distance from its centre: the item's radius, or the one the plan was modelled with
when the item has none) by the pilot's loiter item itself, as it was read from the vehicle
(its command, frame, position, radius, direction and exit flag), after the run's first point
on the circle, its entry, which is kept as a waypoint (a back_to_plan's point on a chord
before it too): the plane starts its circle there, and serve's model of the uploaded mission
(:func:`~gcs_utm.services.fixed_wing_loiter.loiter_points`: a circle entered from a point on
it starts there) puts the circle's points where the plan's are, so the mission read back is
recognised as the plan (``mission_is_plan``: the upload's echo, not a pilot's new mission).
The entry is sent :data:`INWARD_M` inside the circle: from a point outside, the model joins
the circle on its tangent, already 0.9 degrees round 1 cm out.

Its goal leaves the circle where the plan does. ArduPlane goes on round after the goal until
it heads for the next waypoint (``verify_loiter_heading``), so any goal that ends within the
last turn before the plan's exit from the circle leaves it there. The pilot's item as it is
when its own goal does: always when the plan holds the whole loiter (the model went on round
less than a turn after the goal). A plan that starts on the circle (the plane was loitering:
ArduPlane restarts a loiter's goal when its mission is replaced) may hold less than the goal:
NAV_LOITER_TURNS then gets the whole turns of the plan's sweep, NAV_LOITER_TIME the time of
the plan's sweep less half a turn (the middle of that last turn; whole seconds, as ArduPilot
stores it). NAV_LOITER_UNLIM is kept as it is.
"""

from __future__ import annotations

import math
from dataclasses import replace

from adapters.mavlink.mission import MAV_CMD_NAV_WAYPOINT, MissionItem, frame_family, is_nav
from gcs_utm.model import FlightPlan, Waypoint4D

MAV_CMD_NAV_LOITER_UNLIM = 17
MAV_CMD_NAV_LOITER_TURNS = 18
MAV_CMD_NAV_LOITER_TIME = 19
KEPT_LOITERS = frozenset(
    {MAV_CMD_NAV_LOITER_UNLIM, MAV_CMD_NAV_LOITER_TURNS, MAV_CMD_NAV_LOITER_TIME}
)
ON_CIRCLE_M = 2.0
"""Plan points this close (plus :data:`CHORD_FRACTION` of the radius) to one distance from a
loiter's centre are on one circle: the model puts them on it exactly (up to 1e-7 deg and its
flat earth)."""
CHORD_FRACTION = 0.02
"""A back_to_plan joins the plan at the point nearest the plane, on a chord between two circle
points: the middle of a 22.5 degree chord is 1.9 % of the radius inside the circle."""
ALT_M = 1.0  # a circle point is at the loiter's altitude (the model keeps it exactly)
NO_RADIUS_M = 1.0
"""An item radius this small or smaller is the vehicle's default (ArduPlane ``update_loiter``;
ArduPilot reads a NAV_LOITER_TIME's param3 back as +1 or -1, the direction only)."""
ENTRY_M = 0.3  # a run point this close to its farthest from the centre is on the circle
INWARD_M = 0.05
"""The kept entry waypoint is moved this far towards the centre: inside the circle by more
than the 1e-7 deg (1.1 cm) of its position, so that serve's model takes it as the entry."""
MAX_RADIUS_M = 1000.0  # a common distance beyond this is not a loiter's circle
_GLOBAL = 0
_RELATIVE = 3
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0
_TURN_RAD = 2.0 * math.pi


def mission_loiters(mission: list[MissionItem] | None) -> list[MissionItem]:
    """The loiter items (:data:`KEPT_LOITERS`) of a vehicle's mission that have a position."""
    return [
        it
        for it in mission or ()
        if it.command in KEPT_LOITERS and it.seq > 0 and (it.x, it.y) != (0, 0)
    ]


def keep_loiters(
    plan: FlightPlan,
    items: list[MissionItem],
    loiters: list[MissionItem],
    home_alt_m: float | None = None,
) -> list[MissionItem]:
    """``items`` (``plan`` encoded by :func:`~adapters.mavlink.mission.plan_to_mission_items`)
    with each run of waypoints on a loiter's circle replaced by that loiter item (module
    docstring). ``home_alt_m`` resolves a loiter in a relative-altitude frame (None: such a
    loiter is not looked for)."""
    out = items
    for loiter in loiters:
        alt = _alt_amsl_m(loiter, home_alt_m)
        if alt is None:
            continue
        run = _circle_run(plan.waypoints, loiter, alt)
        if run is not None:
            out = _replace_run(out, plan.waypoints, run, loiter)
    return out


def _alt_amsl_m(it: MissionItem, home_alt_m: float | None) -> float | None:
    family = frame_family(it.frame)
    if family == _GLOBAL:
        return it.z
    if family == _RELATIVE and home_alt_m is not None:
        return it.z + home_alt_m
    return None


def _en(centre: MissionItem, w: Waypoint4D) -> tuple[float, float]:
    """``w`` relative to the loiter's centre, metres east and north (flat earth)."""
    k = math.cos(math.radians(centre.lat_deg))
    return (
        (w.lon_deg - centre.lon_deg) * _M_PER_DEG_LON * k,
        (w.lat_deg - centre.lat_deg) * _M_PER_DEG_LAT,
    )


def _circle_run(
    wps: tuple[Waypoint4D, ...], loiter: MissionItem, alt_amsl_m: float
) -> tuple[int, int] | None:
    """The first and last index of the longest run (at least two) of consecutive plan
    waypoints on ``loiter``'s circle, else None."""
    given = abs(loiter.param3) if loiter.param3 and abs(loiter.param3) > NO_RADIUS_M else None
    best: tuple[int, int] | None = None
    start: int | None = None
    radius = 0.0
    for i, w in enumerate([*wps, None]):
        d = math.hypot(*_en(loiter, w)) if w is not None else -1.0
        on = (
            w is not None
            and abs(w.alt_amsl_m - alt_amsl_m) <= ALT_M
            and NO_RADIUS_M < d <= MAX_RADIUS_M
            and (given is None or abs(d - given) <= _tolerance_m(given))
        )
        if on and start is not None and abs(d - radius) <= _tolerance_m(max(d, radius)):
            continue
        if (
            start is not None
            and i - 1 > start
            and (best is None or i - 1 - start > best[1] - best[0])
        ):
            best = (start, i - 1)
        start, radius = (i, d) if on else (None, 0.0)
    return best


def _tolerance_m(radius_m: float) -> float:
    return ON_CIRCLE_M + CHORD_FRACTION * radius_m


def _sweep_rad(wps: tuple[Waypoint4D, ...], loiter: MissionItem, a: int, b: int) -> float:
    """The angle the plan goes round the centre from waypoint ``a`` to ``b``."""
    total = 0.0
    prev = math.atan2(*reversed(_en(loiter, wps[a])))
    for w in wps[a + 1 : b + 1]:
        ang = math.atan2(*reversed(_en(loiter, w)))
        total += abs((ang - prev + math.pi) % _TURN_RAD - math.pi)
        prev = ang
    return total


def _goal(loiter: MissionItem, sweep_rad: float, duration_s: float) -> MissionItem:
    """``loiter`` with the goal that leaves its circle where the plan does, when the plan
    sweeps ``sweep_rad`` round it in ``duration_s`` (module docstring): the item as it is
    when its own goal does (the plan holds the whole loiter, or a plane that restarts it
    where it is still leaves there)."""
    if loiter.command == MAV_CMD_NAV_LOITER_TURNS:
        turns = float(math.floor(sweep_rad / _TURN_RAD + 1e-9))
        return loiter if turns == loiter.param1 else replace(loiter, param1=turns)
    if loiter.command == MAV_CMD_NAV_LOITER_TIME and duration_s > 0.0 and sweep_rad > 0.0:
        rate_rad_s = sweep_rad / duration_s
        if sweep_rad - _TURN_RAD < loiter.param1 * rate_rad_s <= sweep_rad:
            return loiter
        left_s = max(0.0, sweep_rad - math.pi) / rate_rad_s
        return replace(loiter, param1=float(round(left_s)))
    return loiter


def _at(items: list[MissionItem], w: Waypoint4D, after: int = 1) -> int | None:
    """The index of the NAV_WAYPOINT of plan waypoint ``w`` (its position to 1e-7 deg) from
    ``after`` on (ArduPilot's seq 0 is home, made from the plan's first waypoint when the
    vehicle's home is not known)."""
    x, y = round(w.lat_deg * 1e7), round(w.lon_deg * 1e7)
    return next(
        (
            i
            for i in range(after, len(items))
            if items[i].command == MAV_CMD_NAV_WAYPOINT and (items[i].x, items[i].y) == (x, y)
        ),
        None,
    )


def _entry(wps: tuple[Waypoint4D, ...], loiter: MissionItem, a: int, b: int) -> int:
    """The run's first point on the circle itself: a back_to_plan's point on a chord (inside
    the circle) before it is flown as a waypoint."""
    radii = [math.hypot(*_en(loiter, w)) for w in wps[a : b + 1]]
    return a + next(k for k, d in enumerate(radii) if d >= max(radii) - ENTRY_M)


def _inward(it: MissionItem, loiter: MissionItem) -> MissionItem:
    """``it`` moved :data:`INWARD_M` towards the loiter's centre (module docstring)."""
    k = math.cos(math.radians(loiter.lat_deg))
    east = (it.lon_deg - loiter.lon_deg) * _M_PER_DEG_LON * k
    north = (it.lat_deg - loiter.lat_deg) * _M_PER_DEG_LAT
    f = max(0.0, 1.0 - INWARD_M / max(math.hypot(east, north), INWARD_M))
    lat = loiter.lat_deg + north * f / _M_PER_DEG_LAT
    lon = loiter.lon_deg + east * f / (_M_PER_DEG_LON * k)
    return replace(it, x=round(lat * 1e7), y=round(lon * 1e7))


def _replace_run(
    items: list[MissionItem],
    wps: tuple[Waypoint4D, ...],
    run: tuple[int, int],
    loiter: MissionItem,
) -> list[MissionItem]:
    """``items`` with the waypoints of plan waypoints ``run`` after its entry (and the speed
    items between them) replaced by ``loiter`` with its goal left, after the entry's speed
    item; current where one of them was (module docstring)."""
    a, b = _entry(wps, loiter, *run), run[1]
    first = _at(items, wps[a])
    last = None if first is None or a == b else _at(items, wps[b], first + 1)
    if first is None or last is None:
        return items  # (not encoded as waypoints: nothing to replace)
    kept = _goal(loiter, _sweep_rad(wps, loiter, a, b), wps[b].t_s - wps[a].t_s)
    speed = first + 1  # the speed items of the leg after the entry are the loiter's
    while speed <= last and not is_nav(items[speed].command):
        speed += 1
    current = any(it.current for it in items[speed : last + 1])
    entry = _inward(items[first], loiter)
    out = [*items[:first], entry, *items[first + 1 : speed]]
    out += [replace(kept, current=int(current)), *items[last + 1 :]]
    return [replace(it, seq=i) for i, it in enumerate(out)]
