"""A vehicle's downloaded mission as the UTM reads it: its positional items (:class:`NavPoint`,
AMSL, with the speed each is flown at), the 4D plan of flying them from where the vehicle is
(:func:`plan_from_points`), and whether a mission is a given plan (:func:`mission_is_plan`).

Pure functions of the items, the home and the vehicle's position; :mod:`.vehicle_ops` files
and re-times operations with them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from gcs_utm.model import FlightPlan, OperationId, Position, Waypoint4D
from gcs_utm.services import fixed_wing_point as fwp
from gcs_utm.services import mission_order
from gcs_utm.services.fixed_wing_rejoin import rejoin_rest

NAV_WAYPOINT = 16
NAV_LAND = 21
NAV_TAKEOFF = 22
_DO_CHANGE_SPEED = 178
_DO_LAND_START = 189
_NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LAND, NAV_TAKEOFF}) | fwp.LOITER_COMMANDS
ABSOLUTE_FRAMES = frozenset({0, 5})  # MAV_FRAME_GLOBAL(_INT): metres AMSL
_RELATIVE_FRAMES = frozenset({3, 6})  # MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT): metres above home
MATCH_H_M = 0.5  # a mission point within this of a plan waypoint is that waypoint (float32 z)
_MATCH_V_M = 0.5


@dataclass(frozen=True, slots=True)
class NavPoint:
    """A positional mission item: its mission seq, position (AMSL) and the speed it is flown
    to at (the last DO_CHANGE_SPEED before it)."""

    seq: int
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    speed_mps: float
    explicit: bool  # its own lat/lon (not "here": a takeoff or land at 0, 0)
    command: int = NAV_WAYPOINT
    radius_m: float = 0.0  # a loiter's radius (0: the vehicle's default; < 0 anticlockwise)
    # a loiter's turns (NAV_LOITER_TURNS) or seconds (NAV_LOITER_TIME); a take-off's pitch (deg)
    amount: float = 0.0
    landing: bool = False  # in the landing sequence (after a DO_LAND_START)
    exit_xtrack: bool = False  # a loiter's param4 1: the next leg from where it leaves

    def moved(self, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> NavPoint:
        return dataclasses.replace(self, lat_deg=lat_deg, lon_deg=lon_deg, alt_amsl_m=alt_amsl_m)

    def synthetic(self) -> NavPoint:
        """A modelled point (not the item's own position): never compared with a plan."""
        return dataclasses.replace(self, explicit=False)


def mission_points(
    items: Sequence[object],
    *,
    home: Position | None,
    cruise_speed_mps: float,
    skip_first: bool = False,
) -> list[NavPoint] | None:
    """The positional items of a downloaded mission, AMSL; None when an item is relative to a
    home that is not known yet. ``skip_first``: ArduPilot's seq 0 is home, not a waypoint.
    A takeoff or land without a position is where the previous point (else home) is."""
    speed = cruise_speed_mps
    out: list[NavPoint] = []
    landing = False
    for i, it in mission_order.flown_order(items):
        if skip_first and i == 0:
            continue
        command = int(getattr(it, "command", -1))
        landing = landing or command == _DO_LAND_START
        if command == _DO_CHANGE_SPEED:
            value = float(getattr(it, "param2", 0.0))
            if value > 0.0:
                speed = value
            continue
        if command not in _NAV_COMMANDS:
            continue
        frame = int(getattr(it, "frame", 0))
        alt = float(getattr(it, "z", 0.0))
        if frame in _RELATIVE_FRAMES:
            if home is None:
                return None
            alt += home.alt_amsl_m
        elif frame not in ABSOLUTE_FRAMES:
            continue  # terrain or local frames: not resolvable here
        lat = float(getattr(it, "x", 0)) / 1e7
        lon = float(getattr(it, "y", 0)) / 1e7
        explicit = (lat, lon) != (0.0, 0.0)
        if not explicit:
            where = out[-1] if out else home
            if where is None:
                continue
            lat, lon = where.lat_deg, where.lon_deg
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and math.isfinite(alt)):
            continue  # a malformed item is skipped, not fatal
        seq = int(getattr(it, "seq", i))
        radius, amount = mission_order.item_params(it, command)
        xtrack = command in fwp.LOITER_COMMANDS and float(getattr(it, "param4", 0.0)) >= 1.0
        out.append(
            NavPoint(seq, lat, lon, alt, speed, explicit, command, radius, amount, landing, xtrack)
        )
    return out


class _Point(Protocol):
    @property
    def lat_deg(self) -> float: ...
    @property
    def lon_deg(self) -> float: ...
    @property
    def alt_amsl_m(self) -> float: ...


def dist_m(a: _Point, b: _Point) -> float:
    """3D distance (flat earth: mission legs are short)."""
    k = math.cos(math.radians(a.lat_deg))
    return math.hypot(
        (b.lat_deg - a.lat_deg) * 110_540.0,
        (b.lon_deg - a.lon_deg) * 111_320.0 * k,
        b.alt_amsl_m - a.alt_amsl_m,
    )


def plan_from_points(
    points: Sequence[NavPoint],
    op_id: OperationId,
    *,
    t_s: float,
    current_seq: int | None = None,
    position: Position | None = None,
    version: int = 1,
    reason: str = "from the vehicle's mission",
    turn_from_m: float = 0.0,
    course_deg: float | None = None,
    climb_rate_mps: float | None = None,
    descent_rate_mps: float | None = None,
) -> FlightPlan | None:
    """The 4D plan of a vehicle flying ``points`` from ``position`` at ``t_s``: the items
    from ``current_seq`` on (MISSION_CURRENT; all when None), each reached at the speed it is
    flown to. None when there is no point. ``turn_from_m`` (a fixed wing): when the point
    just reached (the one before ``current_seq``) is within that of ``position``, the plan
    goes on through it (the autopilot accepted it early: ArduPlane's WP_RADIUS, 50 m; PX4's
    NPFG switch distance); farther, it goes back onto its leg (``course_deg``: PX4's loiter
    exit; :mod:`.fixed_wing_rejoin`).
    ``climb_rate_mps`` / ``descent_rate_mps`` (the vehicle's envelope; None: no limit): a leg
    that climbs or descends faster at its speed takes as long as that rate needs (a
    multirotor's take-off, landing or steep leg: its autopilot limits the vertical speed)."""
    # from the first point at or after the current item (a loop repeats seqs: its first pass)
    start = next(
        (k for k, p in enumerate(points) if current_seq is None or p.seq >= current_seq),
        len(points),
    )
    rest = list(points[start:])
    if not rest and points:
        rest = [points[-1]]  # mission flown: the last point
    if not rest:
        return None
    done = list(points[:start])
    if (
        position is not None
        and done
        and done[-1].command not in fwp.LOITER_COMMANDS  # a circle is left, not turned round
        and dist_m(position, done[-1]) <= turn_from_m
    ):
        rest = [done[-1], *rest]
    elif position is not None:
        rest = _from_nearest_modelled(rest, position)
        if turn_from_m > 0.0 and done:  # a fixed wing converges on the leg it flies
            rest = rejoin_rest(position.lat_deg, position.lon_deg, course_deg, done[-1], rest)
    wps: list[Waypoint4D] = []
    if position is not None:
        first = rest[0]
        if dist_m(position, first) > MATCH_H_M:
            wps.append(
                Waypoint4D(
                    lat_deg=position.lat_deg,
                    lon_deg=position.lon_deg,
                    alt_amsl_m=position.alt_amsl_m,
                    t_s=t_s,
                )
            )
    for p in rest:
        t = t_s
        if wps:
            a = wps[-1]
            dist = dist_m(a, p)
            t = a.t_s + max(
                dist / max(p.speed_mps, 0.1),
                _vertical_s(p.alt_amsl_m - a.alt_amsl_m, climb_rate_mps, descent_rate_mps),
            )
        wps.append(Waypoint4D(lat_deg=p.lat_deg, lon_deg=p.lon_deg, alt_amsl_m=p.alt_amsl_m, t_s=t))
    return FlightPlan(
        operation_id=op_id, version=version, waypoints=tuple(wps), created_t_s=t_s, reason=reason
    )


def _vertical_s(dz_m: float, climb_rate_mps: float | None, descent_rate_mps: float | None) -> float:
    """How long a climb (``dz_m`` > 0) or descent takes at the given rate (0 without one)."""
    rate = climb_rate_mps if dz_m > 0.0 else descent_rate_mps
    return abs(dz_m) / rate if rate is not None and rate > 0.0 else 0.0


def _from_nearest_modelled(rest: list[NavPoint], position: Position) -> list[NavPoint]:
    """``rest`` from the modelled point of its first item nearest ``position`` on: a vehicle
    part-way along an item's modelled path (a PX4 plane round its landing loiter's circle
    when NAV_LAND becomes current) is not sent back to that path's start."""
    run = next((k for k, p in enumerate(rest) if p.explicit or p.seq != rest[0].seq), len(rest))
    if run < 2:
        return rest
    nearest = min(range(run), key=lambda k: dist_m(position, rest[k]))
    return rest[nearest:]


def mission_is_plan(points: Sequence[NavPoint], plan: FlightPlan) -> bool:
    """True when every waypoint of the mission (with its own position; takeoff and land
    items are not compared, nor the landing sequence when the plan has none of it: uploads
    keep a pilot's landing after the UTM's plan; a fixed wing's circles are points of its
    plan too) is, in order, a waypoint of ``plan`` (within half a metre): the vehicle flies
    the plan (e.g. the UTM uploaded it, from some waypoint on)."""
    wps = plan.waypoints
    compared = [p for p in points if p.explicit and p.command not in (NAV_TAKEOFF, NAV_LAND)]
    landing = [p for p in points if p.landing and p.explicit]  # (its NAV_LAND included)
    if not any(_same_place(p, w) for p in landing for w in wps):
        compared = [p for p in compared if not p.landing]
    k = 0
    for p in compared:
        while k < len(wps) and not _same_place(p, wps[k]):
            k += 1
        if k == len(wps):
            return False
        k += 1
    return True


def _same_place(p: NavPoint, w: Waypoint4D) -> bool:
    k = math.cos(math.radians(p.lat_deg))
    return (
        math.hypot((w.lat_deg - p.lat_deg) * 110_540.0, (w.lon_deg - p.lon_deg) * 111_320.0 * k)
        <= MATCH_H_M
        and abs(w.alt_amsl_m - p.alt_amsl_m) <= _MATCH_V_M
    )
