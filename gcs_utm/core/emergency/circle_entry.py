"""How a fixed wing enters the circle round a new end point: the loop out to two radii.

A fixed wing reaches its last waypoint, the centre of the circle it then flies, along its
last leg, and turns onto the circle on its own turn radius: it loops out beyond the circle
on the side it turns to before it settles (clockwise, to the right of the last leg; the
built-in plane reached 1.5 to 1.9 loiter radii from the end point). EM's moved end point
(:mod:`.endpoint`) was verified with the aircraft on the circle from its arrival, and cleared
the circle of another aircraft by the minima: the loop took it inside them
(``enc_5_0320_crossing``: UAS3's end moved 80 m, 231 m from UAS4's circling end, loops
out 119 m towards it, 39.4 m / 14.1 m against 50 / 50 m). So a moved end point keeps
:func:`entry_reach_m` (two loiter radii) from the other end points, and the plan verified
carries the loop (:func:`entry_loop`): half a turn on the loiter radius to the right of the
arrival heading, out to two radii, then the radius shrinking back to one over the next half
turn. Pure.
"""

from __future__ import annotations

import math

import numpy as np

from gcs_utm.model import FloatArray

REACH_RADII = 2.0
"""How far the entry loop reaches from the end point, in loiter radii."""


def entry_reach_m(radius_m: float) -> float:
    """The farthest a fixed wing entering a circle of ``radius_m`` goes from its centre."""
    return REACH_RADII * radius_m


def entry_loop(
    end: FloatArray, arrive_rad: float, radius_m: float, speed_mps: float, step_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(east, north, time offsets from the arrival) of the loop from ``end``, arriving with
    heading ``arrive_rad`` (east = 0, counter-clockwise), sampled every ``step_s`` (see the
    module doc). The loop ends on the loiter circle, clockwise."""
    # the right turn: its centre is one radius to the right of the arrival heading
    cx = float(end[0]) + radius_m * math.sin(arrive_rad)
    cy = float(end[1]) - radius_m * math.cos(arrive_rad)
    phi0 = math.atan2(float(end[1]) - cy, float(end[0]) - cx)
    half_s = math.pi * radius_m / max(speed_mps, 1e-3)
    t = np.arange(1, math.ceil(2.0 * half_s / step_s) + 1, dtype=np.float64) * step_s
    t = t[t <= 2.0 * half_s]
    out_t = t[t <= half_s]
    e = cx + radius_m * np.cos(phi0 - out_t * speed_mps / radius_m)
    n = cy + radius_m * np.sin(phi0 - out_t * speed_mps / radius_m)
    # then back in: from two radii at the far point, clockwise round the end point
    far = math.atan2(cy - float(end[1]), cx - float(end[0]))
    back_t = t[t > half_s] - half_s
    r = entry_reach_m(radius_m) - (entry_reach_m(radius_m) - radius_m) * back_t / half_s
    ang = far - back_t * speed_mps / (1.5 * radius_m)
    east: FloatArray = np.concatenate([e, float(end[0]) + r * np.cos(ang)])
    north: FloatArray = np.concatenate([n, float(end[1]) + r * np.sin(ang)])
    return east, north, t
