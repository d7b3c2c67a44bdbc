"""Prediction of a fixed wing that has finished its plan: it loiters around its last waypoint.

A fixed wing cannot stop. When its mission ends, PX4 and ArduPilot (and the simulated
vehicle) circle the last waypoint at the loiter radius (PX4's NAV_LOITER_RAD, ArduPlane's
WP_LOITER_RAD; clockwise by default, the sign of the radius turns it around). Extrapolating
such a track with its velocity predicts a straight line along the circle's tangent: a path
the aircraft never flies, that runs into geofences and other UAS beside the circle (and
misses the ones on it). Clamping it to the plan's last point is no better: the circle is up
to one radius away from it.

:func:`loiter_rows` picks the tracks that are loitering: a plan whose end time has passed
at the track's state time, and the track within :data:`CAPTURE_RADII` loiter radii of the
last waypoint (horizontally). :func:`loiter_points` predicts them on the circle: centre the
last waypoint, the phase of the track's current bearing from it, the direction in which it
is turning (clockwise when it does not tell), the angular speed of its horizontal speed on
the radius. The track's radial and vertical offsets from the circle shrink with the time
constant the plan-following prediction uses for its cross-track offset (the autopilot
converges onto the circle and the waypoint's altitude), so the prediction starts at the
track's position.

:func:`overlay` applies both to a prediction (what ``Tracker.predict`` calls). A fixed wing
inside its circle (it has just passed the last waypoint, the centre) swings out on its turn
before it settles on the circle, and one whose plan ends inside the prediction window flies
the same entry after its end, not a stop at the last waypoint: both are predicted with the
capture of :mod:`.loiter_entry`.

Units: local frame metres (east, north, alt AMSL), seconds.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from gcs_utm.core.tracking import kalman, loiter_entry
from gcs_utm.core.tracking.plans import PlanTable
from gcs_utm.model import Operation

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

CAPTURE_RADII = 2.0
"""A track within this many loiter radii of its ended plan's last waypoint is loitering: the
autopilots steer onto the circle from wherever they are (the simulated vehicle from within 3
radii), and a track further away has been sent elsewhere (a reroute ends with a plan)."""

MIN_SPEED_MPS = 1.0
"""Below this horizontal speed the track's bearing and turn tell nothing (a fixed wing is never
that slow in flight): it is extrapolated as any other track."""


def loiter_radius_m(op: Operation) -> float:
    """The circle a vehicle flies around its last waypoint once its plan has ended: its turn
    radius if it cannot hover (a fixed wing), else 0 (it stops there)."""
    env = op.performance()
    return 0.0 if env.can_hover else env.turn_radius_m


def loiter_rows(
    *,
    radius_m: FloatArray,
    t_state_s: FloatArray,
    end_t_s: FloatArray,
    pos: FloatArray,
    vel: FloatArray,
    center: FloatArray,
) -> IntArray:
    """Positions (in these arrays) of the rows that are loitering. ``radius_m`` (N,) is each
    row's loiter radius (0: the vehicle hovers, never loiters), ``t_state_s`` its state time,
    ``end_t_s`` its plan's end, ``pos`` and ``vel`` (N, 3) its state, ``center`` (N, 3) its
    plan's last waypoint."""
    horiz = np.hypot(pos[:, 0] - center[:, 0], pos[:, 1] - center[:, 1])  # m
    speed = np.hypot(vel[:, 0], vel[:, 1])  # m/s
    ok = (
        (radius_m > 0.0)
        & (t_state_s >= end_t_s)
        & (horiz <= CAPTURE_RADII * radius_m)
        & (speed >= MIN_SPEED_MPS)
    )
    out: IntArray = np.flatnonzero(ok)
    return out


def loiter_points(
    *,
    radius_m: FloatArray,
    pos: FloatArray,
    vel: FloatArray,
    center: FloatArray,
    tau_s: FloatArray,
    decay_s: float,
) -> list[FloatArray]:
    """East, north, alt (each (N, K)) of loitering rows at times ``tau_s`` (N, K) after their
    state: on the circle of ``radius_m`` around ``center``, from the row's bearing, at its
    horizontal speed, turning the way it turns; radial and vertical offsets decaying with
    ``decay_s``."""
    de = pos[:, 0] - center[:, 0]  # m
    dn = pos[:, 1] - center[:, 1]  # m
    dist = np.hypot(de, dn)  # m
    speed = np.hypot(vel[:, 0], vel[:, 1])  # m/s
    # Bearing from the centre (radians clockwise from north); at the centre itself, the
    # direction the track flies in (it leaves the centre that way).
    at_center = dist < 1e-6
    bearing0 = np.where(at_center, np.arctan2(vel[:, 0], vel[:, 1]), np.arctan2(de, dn))
    # Clockwise (bearing increasing) unless the velocity runs against the clockwise tangent
    # (cos b, -sin b) of the bearing.
    cw_tangent = vel[:, 0] * np.cos(bearing0) - vel[:, 1] * np.sin(bearing0)  # m/s
    turn = np.where(cw_tangent < 0.0, -1.0, 1.0)
    rate = turn * speed / radius_m  # rad/s
    decay = np.exp(-tau_s / decay_s)
    r = radius_m[:, None] + (dist - radius_m)[:, None] * decay  # m
    bearing = bearing0[:, None] + rate[:, None] * tau_s
    east = center[:, 0, None] + r * np.sin(bearing)
    north = center[:, 1, None] + r * np.cos(bearing)
    alt = center[:, 2, None] + (pos[:, 2] - center[:, 2])[:, None] * decay
    return [east, north, alt]


def overlay(
    axes: list[FloatArray],
    *,
    plans: PlanTable,
    plan_row: IntArray,
    loiter_m: FloatArray,
    t_state_s: FloatArray,
    x: FloatArray,
    ahead0_s: FloatArray,
    steps_s: FloatArray,
    decay_s: float,
) -> None:
    """Overwrite in ``axes`` (east, north, alt; each (N, K)) the rows that are loitering with
    their circle. Per row: ``plan_row`` its plan in ``plans`` (-1: none), ``loiter_m`` its
    loiter radius (0: none), ``t_state_s`` and ``x`` (N, 3, 2) its filter state, ``ahead0_s``
    the time from its state to the first point; ``steps_s`` the points' offsets from the
    first."""
    rows = np.flatnonzero((plan_row >= 0) & (loiter_m > 0.0))
    if not len(rows):
        return
    captures = _Captures()
    _entry_after_end(
        axes,
        captures,
        plans=plans,
        rows=rows,
        plan_row=plan_row,
        loiter_m=loiter_m,
        t_state_s=t_state_s,
        x=x,
        ahead0_s=ahead0_s,
        steps_s=steps_s,
    )
    j = plan_row[rows]
    center = plans.wp_pos[plans.wp_offset[j] + plans.n_waypoints[j] - 1]
    pos = x[rows, :, kalman.POS]
    vel = x[rows, :, kalman.VEL]
    radius = loiter_m[rows]
    at = loiter_rows(
        radius_m=radius,
        t_state_s=t_state_s[rows],
        end_t_s=plans.end_t_s[j],
        pos=pos,
        vel=vel,
        center=center,
    )
    if not len(at):
        captures.run(axes)
        return
    tau = np.add.outer(ahead0_s[rows[at]], steps_s)
    circle = loiter_points(
        radius_m=radius[at],
        pos=pos[at],
        vel=vel[at],
        center=center[at],
        tau_s=tau,
        decay_s=decay_s,
    )
    # Inside the circle (just past the centre): the entry's swing out, on the capture.
    inside = np.flatnonzero(np.hypot(*(pos[at, :2] - center[at, :2]).T) < radius[at])
    for axis in range(3):
        axes[axis][rows[at]] = circle[axis]
    a = at[inside]
    speed = np.hypot(vel[a, 0], vel[a, 1])
    course = np.arctan2(vel[a, 0], vel[a, 1])
    for i, row in enumerate(inside):
        captures.add(
            row=int(rows[a[i]]),
            cols=np.arange(len(steps_s)),
            center_en=center[a[i], :2],
            radius_m=float(radius[a[i]]),
            pos_en=pos[a[i], :2],
            course_rad=float(course[i]),
            speed_mps=float(speed[i]),
            tau_s=tau[row],
        )
    captures.run(axes)


def last_course_rad(wp_pos: FloatArray) -> float | None:
    """The course (radians clockwise from north) of the last leg with a horizontal length of
    the waypoints ``wp_pos`` (K, >= 2; a plan may end with a hold at its last point), or
    None when they never move horizontally."""
    end = wp_pos[-1]
    for i in range(len(wp_pos) - 2, -1, -1):
        d_e, d_n = float(end[0] - wp_pos[i, 0]), float(end[1] - wp_pos[i, 1])
        if math.hypot(d_e, d_n) > 1e-6:
            return math.atan2(d_e, d_n)
    return None


def _entry_after_end(
    axes: list[FloatArray],
    captures: _Captures,
    *,
    plans: PlanTable,
    rows: IntArray,
    plan_row: IntArray,
    loiter_m: FloatArray,
    t_state_s: FloatArray,
    x: FloatArray,
    ahead0_s: FloatArray,
    steps_s: FloatArray,
) -> None:
    """Add to ``captures`` the points of ``axes`` after the plan's end of ``rows`` (fixed
    wings with a plan) whose plan ends after their state and inside the window, and whose
    prediction at the end reaches the last waypoint (within :data:`CAPTURE_RADII` loiter
    radii: not sent elsewhere): from the last waypoint, at the plan's end, on the last leg's
    course at the track's horizontal speed, capturing the circle (:mod:`.loiter_entry`).
    Altitudes stay as predicted."""
    end_all = plans.end_t_s[plan_row[rows]]
    last_t = t_state_s[rows] + ahead0_s[rows] + steps_s[-1]  # the window's last point
    ending = rows[(t_state_s[rows] < end_all) & (end_all < last_t)]
    for r in ending:
        j = int(plan_row[r])
        end_t = float(plans.end_t_s[j])
        tau = ahead0_s[r] + steps_s  # after the state
        after = np.flatnonzero(t_state_s[r] + tau > end_t)
        if t_state_s[r] >= end_t or not len(after) or after[0] == 0:
            continue
        o, m = int(plans.wp_offset[j]), int(plans.n_waypoints[j])
        wps = plans.wp_pos[o : o + m]
        k = int(after[0]) - 1  # the last point up to the end
        reach_m = math.hypot(axes[0][r, k] - wps[-1, 0], axes[1][r, k] - wps[-1, 1])
        course = last_course_rad(wps) if m >= 2 else None
        if course is None or reach_m > CAPTURE_RADII * float(loiter_m[r]):
            continue
        speed = math.hypot(x[r, 0, kalman.VEL], x[r, 1, kalman.VEL])
        if speed < MIN_SPEED_MPS:
            continue
        captures.add(
            row=int(r),
            cols=after,
            center_en=wps[-1, :2],
            radius_m=float(loiter_m[r]),
            pos_en=wps[-1, :2],
            course_rad=course,
            speed_mps=speed,
            tau_s=t_state_s[r] + tau[after] - end_t,
        )


class _Captures:
    """The captures (:func:`.loiter_entry.capture_points`) one prediction needs, collected
    and then integrated in one call (its cost is per call, not per row): for each, the row
    and the columns of the axes it overwrites (east and north), its circle, start and times
    (the row's columns, from its start)."""

    def __init__(self) -> None:
        self._rows: list[tuple[int, IntArray, FloatArray, float, FloatArray, float, float]] = []
        self._tau: list[FloatArray] = []

    def add(
        self,
        *,
        row: int,
        cols: IntArray,
        center_en: FloatArray,
        radius_m: float,
        pos_en: FloatArray,
        course_rad: float,
        speed_mps: float,
        tau_s: FloatArray,
    ) -> None:
        """One clockwise capture of the circle of ``radius_m`` round ``center_en`` from
        ``pos_en`` on ``course_rad`` at ``speed_mps``, at ``tau_s`` (one per column of
        ``cols``) from its start, written into ``row``."""
        self._rows.append((row, cols, center_en, radius_m, pos_en, course_rad, speed_mps))
        self._tau.append(tau_s)

    def run(self, axes: list[FloatArray]) -> None:
        """Integrate every capture added and write it into ``axes`` (east, north)."""
        if not self._rows:
            return
        n = len(self._rows)
        # One rectangle of times: shorter rows padded with 0 (their start: no longer
        # integration), the padding read back nowhere.
        tau = np.zeros((n, max(len(t) for t in self._tau)))
        for i, t in enumerate(self._tau):
            tau[i, : len(t)] = t
        speed = np.array([c[6] for c in self._rows])
        east, north = loiter_entry.capture_points(
            center_en=np.array([c[2] for c in self._rows]),
            radius_m=np.array([c[3] for c in self._rows]),
            turn_radius_m=loiter_entry.capture_turn_radius_m(speed),
            clockwise=np.ones(n, dtype=bool),
            pos_en=np.array([c[4] for c in self._rows]),
            course_rad=np.array([c[5] for c in self._rows]),
            speed_mps=speed,
            tau_s=tau,
        )
        for i, (row, cols, *_) in enumerate(self._rows):
            m = len(cols)
            axes[0][row, cols], axes[1][row, cols] = east[i, :m], north[i, :m]
