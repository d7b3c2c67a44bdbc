"""Turn away: the immediate command of a fixed wing whose hold, climb or descent is too slow.

A fixed wing cannot stop: held, or sent to climb or descend in place, it circles where it is
commanded, and :mod:`.immediate` counts it anywhere within two turn radii of there. With a
few seconds of warning that room covers the other UAS, and neither it nor its climb rate
(5 m/s against a 40-50 m vertical minimum) separates it in time. What it can do at once is
turn: on late encounters (a fixed wing head-on with a multirotor 4.6 s before the loss, the
command acting 2 s later) a turn of the fixed wing away from the other kept the horizontal
minimum where every hold, climb and descent was flown inside it.

The command is a GOTO (MAVLink DO_REPOSITION) at the vehicle's altitude to a point abeam, 90
degrees left or right of its track, so far away (its top speed over the whole look-ahead,
plus four turn radii) that it flies towards it for the rest of the look-ahead rather than
circling it (PX4, ArduPlane and the built-in fixed wing circle a reposition point only once
within a few loiter radii of it). It is flown forward like the other commands: the track's
velocity until the command acts, then a turn at the envelope's turn radius towards the point
(the slower turn of the UTM's envelope, not the tighter one the vehicle may fly), then
straight on. Pure.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.model import Command, CommandKind, FloatArray, Operation, Position

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction import TacticalDeconfliction

SUBSTEP_S = 0.1
"""Integration step of the turn between the grid's points."""
CAPTURE_RADII = 4.0
"""The point lies this many turn radii beyond where the vehicle could be at the look-ahead's
end: the autopilots start circling a reposition point within about three loiter radii."""


_SIDES = (("", 0.0), ("left", math.pi / 2.0), ("right", -math.pi / 2.0))
"""Straight on (first: of two that separate as well, the one nearer its plan), left, right."""
VERTICAL = ("", "climb", "descend")
"""How a turning (or straight-flying) fixed wing changes altitude: not, up or down."""


def turn_moves(
    td: TacticalDeconfliction,
    op: Operation,
    path: LocalPlan,
    grid: FloatArray,
    *,
    t_cmd: float,
    targets_z: dict[str, float] | None = None,
) -> list[tuple[str, FloatArray, Command]]:
    """A turn left and a turn right for a fixed wing ``op`` flying ``path`` until ``t_cmd``,
    at its altitude and, for each of ``targets_z`` ("climb", "descend": the altitude it goes
    to), climbing or descending to it at its envelope's rate while it turns, and straight
    ahead while it climbs or descends: (the action's name, its positions on ``grid``, the
    command) each; none for a multirotor, a vehicle without a turn radius, or one not
    moving."""
    env = op.performance()
    r = env.turn_radius_m
    if env.can_hover or r <= 0.0:
        return []
    e, n, z = path.coords(grid)
    before = np.column_stack((e, n, z))
    e0, n0, z0 = (float(c[0]) for c in path.coords(np.array([t_cmd])))
    e1, n1, _ = (float(c[0]) for c in path.coords(np.array([t_cmd + 0.5])))
    speed = math.hypot(e1 - e0, n1 - n0) / 0.5
    if speed < 1.0:
        return []
    course = math.atan2(n1 - n0, e1 - e0)  # radians from east, counter-clockwise
    far = max(env.max_speed_mps, speed) * float(grid[-1] - t_cmd) + CAPTURE_RADII * r
    after = grid >= t_cmd
    tau = grid[after] - t_cmd
    rates = {"climb": env.climb_rate_mps, "descend": env.descent_rate_mps}
    out = []
    to = {"": z0, **(targets_z or {})}
    for vertical in VERTICAL:
        if vertical not in to:
            continue  # no room in the altitude band that way
        to_z = to[vertical]
        for side_name, side_rad in _SIDES:
            if not side_name and not vertical:
                continue  # straight on, level: that is flying on
            heading = course + side_rad
            goal = (e0 + far * math.cos(heading), n0 + far * math.sin(heading))
            xyz = before.copy()
            xyz[after] = _flown(grid[after], t_cmd, (e0, n0, z0), course, speed, r, goal)
            rate = rates.get(vertical, 0.0)
            xyz[after, 2] = z0 + np.clip(to_z - z0, -rate * tau, rate * tau)
            lat, lon = td.frame.point_to_wgs84(goal[0], goal[1])
            target = Position(lat_deg=lat, lon_deg=lon, alt_amsl_m=to_z)
            cmd = Command(kind=CommandKind.GOTO, operation_id=op.id, target=target)
            out.append((_name(side_name, vertical), xyz, cmd))
    return out


def _name(side: str, vertical: str) -> str:
    """The audit's name of a turn ("turn left", "turn right and climb", "descend ahead")."""
    if not side:
        return f"{vertical} ahead"
    return f"turn {side}" + (f" and {vertical}" if vertical else "")


def _flown(  # noqa: PLR0917 - the turn's state, positional
    times: FloatArray,
    t0: float,
    start: tuple[float, float, float],
    course: float,
    speed: float,
    radius_m: float,
    goal: tuple[float, float],
) -> FloatArray:
    """Positions at ``times`` (from ``t0`` on) of a vehicle at ``start`` on ``course`` that
    turns towards ``goal`` at ``speed / radius_m`` rad/s and then flies straight at it."""
    rate = speed / radius_m
    e, n, z = start
    t = t0
    out = np.empty((times.shape[0], 3))
    for i, ti in enumerate(times):
        while t < ti - 1e-9:
            dt = min(SUBSTEP_S, ti - t)
            want = math.atan2(goal[1] - n, goal[0] - e)
            err = (want - course + math.pi) % (2.0 * math.pi) - math.pi
            course += max(-rate * dt, min(rate * dt, err))
            e += speed * math.cos(course) * dt
            n += speed * math.sin(course) * dt
            t += dt
        out[i] = (e, n, z)
    return out
