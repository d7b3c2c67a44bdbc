"""How a fixed wing enters the circle round a new end point: the loop out past the circle.

A fixed wing reaches its last waypoint, the centre of the circle it then flies, along its
last leg, and turns onto the circle on its own turn radius: it loops out beyond the circle
on the side it turns to before it settles. EM's moved end point (:mod:`.endpoint`) was
verified with the aircraft on the circle from its arrival, and cleared the circle of another
aircraft by the minima: the loop took it inside them (``enc_5_0320_crossing``: UAS3's end
moved 80 m, 231 m from UAS4's circling end, loops out 119 m towards it, 39.4 m / 14.1 m
against 50 / 50 m). So a moved end point keeps :func:`entry_reach_m` from the other end
points, and the plan verified carries the loop (:func:`entry_loop`).

The loop itself is the tracker's model of the capture
(:func:`gcs_utm.core.tracking.loiter_entry.capture_points`): one model of the turn for
Tracking, Monitoring and EM. Pure.
"""

from __future__ import annotations

import math

import numpy as np

from gcs_utm.core.tracking.loiter_entry import capture_points, capture_turn_radius_m
from gcs_utm.model import FloatArray

REACH_RADII = 2.0
"""How far the entry loop reaches from the end point, in radii: the larger of the loiter
radius and the capture's turn radius (the modelled loop from the centre reaches about two
turn radii: 152 m at 22.7 m/s)."""


def entry_reach_m(radius_m: float, speed_mps: float) -> float:
    """The farthest a fixed wing at ``speed_mps`` entering a circle of ``radius_m`` goes from
    its centre (a bound on :func:`entry_loop`)."""
    turn_m = float(capture_turn_radius_m(np.array([speed_mps]))[0])
    return REACH_RADII * max(radius_m, turn_m)


def entry_loop(
    end: FloatArray, arrive_rad: float, radius_m: float, speed_mps: float, step_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(east, north, time offsets from the arrival) of the loop from ``end``, arriving with
    heading ``arrive_rad`` (east = 0, counter-clockwise), sampled every ``step_s``, for one
    lap of the circle's time: the capture of a clockwise circle of ``radius_m`` round
    ``end`` at ``speed_mps``, as the tracker predicts it."""
    speed = max(speed_mps, 1e-3)
    lap_s = 2.0 * math.pi * max(radius_m, float(capture_turn_radius_m(np.array([speed]))[0]))
    t = np.arange(1, math.ceil(lap_s / speed / step_s) + 1, dtype=np.float64) * step_s
    course = math.pi / 2.0 - arrive_rad  # clockwise from north
    east, north = capture_points(
        center_en=np.array([[float(end[0]), float(end[1])]]),
        radius_m=np.array([radius_m]),
        turn_radius_m=capture_turn_radius_m(np.array([speed])),
        clockwise=np.array([True]),
        pos_en=np.array([[float(end[0]), float(end[1])]]),
        course_rad=np.array([course]),
        speed_mps=np.array([speed]),
        tau_s=t[None, :],
    )
    return east[0], north[0], t
