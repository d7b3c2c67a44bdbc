"""The band a fixed wing flies around its plan's polyline, for conformance. Pure.

A plan is a polyline; a fixed wing does not fly one (docs/monitoring.md, "Fixed wings"):
- **Turns.** It cannot turn on the spot. Inside a corner it may cut it on an arc of its
  turn radius ``R`` (the envelope's; ``v^2 / (g tan(roll_limit))``, ArduPlane ROLL_LIMIT_DEG,
  PX4 FW_R_LIM): the band holds the region between the legs and the arc tangent to both
  (the kite O-A-C-B of the arc's centre O, its tangent points A and B, the corner C); a
  vehicle there is on its plan, inside the arc it is that far from it (a vehicle turning
  tighter than ``R`` is inside the band too). Outside, it starts its turn at the latest
  :data:`TURN_START_M` before the waypoint (ArduPlane accepts a waypoint WP_RADIUS early) and,
  turning on ``R``, runs on up to ``min(R, R (1 - cos(theta)) - TURN_START_M sin(theta))``
  outside the next leg for ``R`` past the corner, then converges back to it by ``3 R``.
  Measured on real ArduPlane 4.6 (22-24 m/s, ROLL_LIMIT_DEG 65, NAVL1_PERIOD 15 in its SITL
  defaults): it started its turns about 50 m before the waypoints and ran 26, 31 and 41 m
  outside the next leg after turns of 90, 101 and 124 deg (about 100 m past the corner,
  back within 10 m 200 m past it), where the allowance is 30, 46 and 80 m with R = 80 m.
- **Climbs and descents.** ArduPlane in AUTO climbs at once (TECS, up to its climb rate)
  towards a higher waypoint below 20 m above home or with FLIGHT_OPTIONS bit 14
  (IMMEDIATE_CLIMB_IN_AUTO), and flies a glide slope (the straight line) otherwise and when
  descending; climbing first it ran 21 m above the straight 30 m climb of a 1600 m leg. So
  vertically a leg is the band between the straight line and "climb first": from the leg's
  start at the steepest gradient of the envelope (climb rate over minimum speed, descent
  rate over minimum speed for a descent) until the leg's end altitude.
- **Loiters.** A circle of its plan is the ring it flies round it (loiter_band.py).
The band is used only for vehicles that cannot hover; a multirotor flies its polyline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from gcs_utm.core.monitoring.checks import PlanTable
from gcs_utm.core.monitoring.geometry import FloatArray
from gcs_utm.core.monitoring.loiter_band import loiter_distance
from gcs_utm.model import Operation

_MIN_LEG_M = 0.5  # shorter horizontal legs are climbs on the spot or padding: no band
_MAX_TURN_RAD = math.pi - 0.02  # a U-turn's tangent points are bounded by the legs anyway
TURN_START_M = 50.0
"""How far before a waypoint a fixed wing starts its turn at the latest: ArduPlane accepts a
waypoint WP_RADIUS before it (50 m in its SITL defaults)."""


def band_parameters(ops: Sequence[Operation]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per operation: turn radius (m; 0 for a vehicle that can hover: no band), steepest
    climb and descent gradients (m of height per m flown)."""
    radius = np.zeros(len(ops))
    climb = np.zeros(len(ops))
    descent = np.zeros(len(ops))
    for k, op in enumerate(ops):
        env = op.performance()
        if env.can_hover:
            continue
        slowest = max(env.min_speed_mps, 1.0)
        radius[k] = env.turn_radius_m
        climb[k] = env.climb_rate_mps / slowest
        descent[k] = env.descent_rate_mps / slowest
    return radius, climb, descent


def band_distance(
    table: PlanTable,
    pos: FloatArray,
    window: tuple[FloatArray, FloatArray],
    params: tuple[FloatArray, FloatArray, FloatArray],
) -> FloatArray:
    """Distance (M,) from positions (M, 3) to each plan's band (module docstring) within the
    plan times ``window`` (earliest, latest; per row); inf for a row without a band (a
    vehicle that can hover) or no part of the band in the window."""
    radius, climb, descent = params
    legs = _leg_distance(table.points, pos, window, climb, descent)
    corners = _corner_distance(table.points, pos, window, radius)
    rings = loiter_distance(table.points, pos, window)  # its loiters' circles (loiter_band)
    out: FloatArray = np.where(radius > 0.0, np.minimum(np.minimum(legs, corners), rings), np.inf)
    return out


def _leg_distance(
    p: FloatArray,
    pos: FloatArray,
    window: tuple[FloatArray, FloatArray],
    climb: FloatArray,
    descent: FloatArray,
) -> FloatArray:
    """Distance to the legs with their vertical band (horizontal nearest point on the part
    of the leg in the window, vertical distance to the band there)."""
    p0, p1 = p[:, :-1], p[:, 1:]  # (M, K-1, 4)
    ta, tb = p0[..., 3], p1[..., 3]
    lo_t, hi_t = window[0][:, None], window[1][:, None]
    dur = np.where(tb > ta, tb - ta, 1.0)
    u0 = np.clip((lo_t - ta) / dur, 0.0, 1.0)
    u1 = np.clip((hi_t - ta) / dur, 0.0, 1.0)
    overlap = (tb >= lo_t) & (ta <= hi_t)
    dxy = p1[..., :2] - p0[..., :2]  # m
    length2 = (dxy * dxy).sum(axis=-1)  # m^2
    flat = length2 >= _MIN_LEG_M * _MIN_LEG_M
    rel = pos[:, None, :2] - p0[..., :2]
    u = np.clip((rel * dxy).sum(axis=-1) / np.where(flat, length2, 1.0), u0, u1)
    dh = np.hypot(*np.moveaxis(rel - u[..., None] * dxy, -1, 0))  # m
    z0, z1 = p0[..., 2], p1[..., 2]
    line = z0 + u * (z1 - z0)  # m, the straight climb
    run = u * np.sqrt(length2)  # m flown along the leg
    first_up = np.minimum(z1, z0 + run * climb[:, None])  # climb first
    first_down = np.maximum(z1, z0 - run * descent[:, None])  # descend first
    top = np.where(z1 > z0, np.maximum(line, first_up), line)
    bottom = np.where(z1 < z0, np.minimum(line, first_down), line)
    z = pos[:, None, 2]
    dv = np.maximum(np.maximum(bottom - z, z - top), 0.0)
    d = np.where(overlap & flat, np.hypot(dh, dv), np.inf)
    out: FloatArray = d.min(axis=1) if d.shape[1] else np.full(len(pos), np.inf)
    return out


def _corner_distance(
    p: FloatArray, pos: FloatArray, window: tuple[FloatArray, FloatArray], radius: FloatArray
) -> FloatArray:
    """Distance to the corner kites (module docstring) of the interior waypoints."""
    if p.shape[1] < 3:
        return np.full(len(pos), np.inf)
    prev, corner, nxt = p[:, :-2], p[:, 1:-1], p[:, 2:]  # (M, K-2, 4)
    a = corner[..., :2] - prev[..., :2]
    b = nxt[..., :2] - corner[..., :2]
    la, lb = np.hypot(a[..., 0], a[..., 1]), np.hypot(b[..., 0], b[..., 1])
    real = (la >= _MIN_LEG_M) & (lb >= _MIN_LEG_M)
    ua = a / np.where(real, la, 1.0)[..., None]
    ub = b / np.where(real, lb, 1.0)[..., None]
    cross = ua[..., 0] * ub[..., 1] - ua[..., 1] * ub[..., 0]
    dot = (ua * ub).sum(axis=-1)
    turn = np.minimum(np.arctan2(np.abs(cross), dot), _MAX_TURN_RAD)  # rad
    half_tan = np.tan(turn / 2.0)
    # tangent points this far from the corner, never beyond the legs' other ends
    reach = np.minimum(radius[:, None] * half_tan, np.minimum(la, lb))  # m
    r = np.where(half_tan > 1e-9, reach / np.maximum(half_tan, 1e-9), 0.0)  # m, the arc's
    side = np.where(cross >= 0.0, 1.0, -1.0)  # +1: a left turn
    na = side[..., None] * np.stack([-ua[..., 1], ua[..., 0]], axis=-1)  # inner normals
    nb = side[..., None] * np.stack([-ub[..., 1], ub[..., 0]], axis=-1)
    c = corner[..., :2]
    pa = c - reach[..., None] * ua  # tangent points
    pb = c + reach[..., None] * ub
    centre = pa + r[..., None] * na
    q = pos[:, None, :2]
    kite = (
        (((q - pa) * ua).sum(axis=-1) >= 0.0)
        & (((q - pb) * ub).sum(axis=-1) <= 0.0)
        & (((q - c) * na).sum(axis=-1) >= 0.0)
        & (((q - c) * nb).sum(axis=-1) >= 0.0)
    )
    off = np.hypot(*np.moveaxis(q - centre, -1, 0))
    dh = np.maximum(r - off, 0.0)  # inside the arc: that far from it
    # its altitudes and times: those of the legs at the tangent points, and the corner's
    fa = reach / np.where(real, la, 1.0)
    fb = reach / np.where(real, lb, 1.0)
    za = corner[..., 2] + fa * (prev[..., 2] - corner[..., 2])
    zb = corner[..., 2] + fb * (nxt[..., 2] - corner[..., 2])
    low = np.minimum(np.minimum(za, zb), corner[..., 2])
    high = np.maximum(np.maximum(za, zb), corner[..., 2])
    z = pos[:, None, 2]
    dv = np.maximum(np.maximum(low - z, z - high), 0.0)
    t_a = corner[..., 3] + fa * (prev[..., 3] - corner[..., 3])
    t_b = corner[..., 3] + fb * (nxt[..., 3] - corner[..., 3])
    in_time = (t_b >= window[0][:, None]) & (t_a <= window[1][:, None])
    d = np.where(real & kite & in_time & (reach > 0.0), np.hypot(dh, dv), np.inf)
    d = np.minimum(d, _overshoot(_Corners(corner, nxt, ub, nb, turn), radius, pos, window))
    out: FloatArray = d.min(axis=1)
    return out


class _Corners(NamedTuple):
    """The interior waypoints (M, K-2, 4), the next ones, the outgoing legs' directions and
    inner normals (M, K-2, 2), the turns (rad)."""

    corner: FloatArray
    nxt: FloatArray
    ub: FloatArray
    nb: FloatArray
    turn: FloatArray


def _overshoot(
    c: _Corners, radius: FloatArray, pos: FloatArray, window: tuple[FloatArray, FloatArray]
) -> FloatArray:
    """Distance to the overshoot region outside each outgoing leg (module docstring): up to
    ``min(R, R (1 - cos(theta)) - d sin(theta))`` outside it for ``R`` past the corner, then
    back to the leg by ``3 R``."""
    corner, nxt, ub, nb, turn = c
    r = radius[:, None]
    peak = np.clip(r * (1.0 - np.cos(turn)) - TURN_START_M * np.sin(turn), 0.0, r)  # m
    lb = np.hypot(*np.moveaxis(nxt[..., :2] - corner[..., :2], -1, 0))
    rel = pos[:, None, :2] - corner[..., :2]
    along = (rel * ub).sum(axis=-1)  # m past the corner
    outside = -(rel * nb).sum(axis=-1)  # m outside the leg (nb is the inner normal)
    span = np.minimum(3.0 * r, lb)  # m
    allowed = peak * np.clip((3.0 * r - along) / np.maximum(2.0 * r, 1e-9), 0.0, 1.0)
    dh = np.maximum(outside - allowed, 0.0)
    frac = np.clip(along / np.where(lb > 0.0, lb, 1.0), 0.0, 1.0)
    z = corner[..., 2] + frac * (nxt[..., 2] - corner[..., 2])
    low = np.minimum(z, corner[..., 2])
    high = np.maximum(z, corner[..., 2])
    zp = pos[:, None, 2]
    dv = np.maximum(np.maximum(low - zp, zp - high), 0.0)
    t_end = corner[..., 3] + span / np.where(lb > 0.0, lb, 1.0) * (nxt[..., 3] - corner[..., 3])
    in_time = (t_end >= window[0][:, None]) & (corner[..., 3] <= window[1][:, None])
    there = (along >= 0.0) & (along <= span) & (outside >= 0.0) & (peak > 0.0) & (lb >= _MIN_LEG_M)
    out: FloatArray = np.where(there & in_time, np.hypot(dh, dv), np.inf)
    return out
