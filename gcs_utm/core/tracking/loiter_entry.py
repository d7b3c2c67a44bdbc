"""A fixed wing entering its loiter circle from inside it: the swing out past the circle.

A fixed wing's plan ends at its loiter's centre (the last waypoint): it arrives there along
its last leg and must then turn onto a circle of the loiter radius round the point it is
flying over, on a turn radius about as large as that circle. It cannot: the capture (course
towards the circle's tangent, with a correction towards the circle for the radial error,
at the turn rate its bank limit allows) turns it to the loiter's side all the way, and the
loop reaches up to about two turn radii from the centre, on that side of the last leg and
ahead of it, before the aircraft settles on the circle (the simulated plane: 142-150 m from
the end point for an 80 m loiter, ``enc_4_0160_crossing``, ``enc_3_0443_endpoint_vertical``).
Predicting the circle from there (:func:`.loiter.loiter_points`, its radial offset decaying)
never goes beyond the circle, so a UAS or a fence in the loop was first predicted when the
track was already out in it.

:func:`capture_points` integrates that capture for rows of tracks (few: the fixed wings
inside their circle or reaching their plan's end inside the prediction window). The loop's
size comes from the turn radius, not from the autopilot's tuning: the course correction
towards the circle (up to :data:`CORRECTION_RAD` for an error of one radius) and the
heading gain (:data:`HEADING_GAIN_PER_S`) only shape how it settles.

Units: local frame metres (east, north), seconds, radians clockwise from north.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from gcs_utm.envelope import turn_radius_m

FloatArray = npt.NDArray[np.float64]

STEP_S = 0.25
"""Integration step: at 25 m/s on an 80 m radius the course turns 4.5 degrees per step (the
midpoint rule keeps the arc within centimetres)."""

CORRECTION_RAD = math.pi / 3.0
"""Course correction towards the circle for a radial error of one radius or more."""

HEADING_GAIN_PER_S = 2.0
"""Turn rate per radian of course error, before the turn radius limits it."""

CAPTURE_BANK_DEG = 35.0
"""The bank the capture turns at: the smallest roll limit of the fixed wings the UTM flies
(the built-in plane 35 degrees, ArduPlane's ROLL_LIMIT_DEG 45, PX4's FW_R_LIM 50), so the
widest loop at a given speed (76 m at 22.7 m/s, 37 m at 16 m/s)."""


def capture_turn_radius_m(speed_mps: FloatArray) -> FloatArray:
    """The radius the capture turns on at ``speed_mps`` (horizontal): a coordinated turn at
    :data:`CAPTURE_BANK_DEG`."""
    unit = turn_radius_m(1.0, CAPTURE_BANK_DEG)  # m per (m/s)^2
    out: FloatArray = unit * np.square(speed_mps)
    return out


def capture_points(
    *,
    center_en: FloatArray,
    radius_m: FloatArray,
    turn_radius_m: FloatArray,
    clockwise: npt.NDArray[np.bool_],
    pos_en: FloatArray,
    course_rad: FloatArray,
    speed_mps: FloatArray,
    tau_s: FloatArray,
    step_s: float = STEP_S,
) -> tuple[FloatArray, FloatArray]:
    """East and north (each (N, K)) at times ``tau_s`` (N, K; from the state, >= 0) of N
    aircraft capturing their loiter circle: centre ``center_en`` (N, 2), radius ``radius_m``,
    turning ``clockwise`` (else counter-clockwise) at most at ``speed_mps / turn_radius_m``,
    from ``pos_en`` (N, 2) on ``course_rad`` at ``speed_mps`` (horizontal, kept), integrated
    in steps of ``step_s``.

    The rows do not depend on each other: many rows in one call cost about what one does (the
    cost is numpy's per call, a few dozen calls per step), and a row's figures are the same
    whichever rows it is integrated with (a longer integration only adds later points)."""
    n, k = tau_s.shape
    east_out = np.empty((n, k))
    north_out = np.empty((n, k))
    if n == 0 or k == 0:
        return east_out, north_out
    speed = np.maximum(speed_mps, 1e-3)
    max_rate = speed / np.maximum(turn_radius_m, 1.0)  # rad/s
    n_steps = max(1, math.ceil(float(tau_s.max()) / step_s))
    path = _integrate(
        center_en=center_en.astype(np.float64),
        radius=np.maximum(radius_m, 1.0),
        max_rate=max_rate,
        side=None if bool(np.all(clockwise)) else np.where(clockwise, 1.0, -1.0),
        pos_en=pos_en.astype(np.float64, copy=True),
        course_rad=course_rad.astype(np.float64, copy=True),
        step_m=np.repeat(speed * step_s, 2).reshape(n, 2),
        step_s=step_s,
        n_steps=n_steps,
    )
    grid_t = np.arange(n_steps + 1) * step_s
    for r in range(n):
        east_out[r] = np.interp(tau_s[r], grid_t, path[:, r, 0])
        north_out[r] = np.interp(tau_s[r], grid_t, path[:, r, 1])
    return east_out, north_out


def _integrate(
    *,
    center_en: FloatArray,
    radius: FloatArray,
    max_rate: FloatArray,
    side: FloatArray | None,
    pos_en: FloatArray,
    course_rad: FloatArray,
    step_m: FloatArray,
    step_s: float,
    n_steps: int,
) -> FloatArray:
    """(n_steps + 1, N, 2) east and north every ``step_s`` from ``pos_en`` (N, 2; the first
    point) of :func:`capture_points`: ``side`` +1 clockwise, -1 counter-clockwise (None: all
    clockwise), ``step_m`` (N, 2) each row's distance per step on both columns. Each step
    steers towards the circle's tangent, corrected towards the circle for the radial error,
    at most at ``max_rate``, and moves on the course at the middle of the step (the midpoint
    rule). Written as few numpy calls per step as possible: their count, not the rows, is
    the cost."""
    path = np.empty((n_steps + 1, len(pos_en), 2))
    p, c = pos_en, course_rad
    path[0] = p
    min_rate = -max_rate
    sin_cos = np.empty_like(pos_en)
    sin_col, cos_col = sin_cos[:, 0], sin_cos[:, 1]
    half_s = step_s / 2.0
    for i in range(1, n_steps + 1):
        d = p - center_en
        dist = np.hypot(d[:, 0], d[:, 1])
        # bearing of the aircraft from the centre; at the centre, the way it flies out
        radial = np.where(dist < 1e-6, c, np.arctan2(d[:, 0], d[:, 1]))
        err = np.minimum(np.maximum((dist - radius) / radius, -1.0), 1.0)
        off = math.pi / 2.0 + err * CORRECTION_RAD  # from the radial, on the turn's side
        want = radial + (off if side is None else side * off)
        wrapped = (want - c + math.pi) % (2.0 * math.pi) - math.pi  # course error
        rate = np.minimum(np.maximum(HEADING_GAIN_PER_S * wrapped, min_rate), max_rate)
        mid = c + rate * half_s
        np.sin(mid, sin_col)
        np.cos(mid, cos_col)
        p = p + step_m * sin_cos
        c = c + rate * step_s
        path[i] = p
    return path
