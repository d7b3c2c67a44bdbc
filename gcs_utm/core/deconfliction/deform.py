"""A plan through a displaced charged cord, timed inside the vehicle's envelope.

The displacement is piecewise linear on the cord grid (an envelope of cones, capped), so the
new plan needs points only at the filed waypoints and at the grid times where the
displacement's slope changes: between those it is exactly the cord. Each segment then takes
at least its original time and at least what the vehicle needs for it: horizontal speed up to
its original pace or the cruise speed times ``max_speed_factor`` (never above the envelope's
maximum unless the filed plan was already faster), climbs at the envelope's climb rate and
descents at its descent rate (or the filed pace where that was steeper).
"""

from __future__ import annotations

import numpy as np

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.envelope import PerformanceEnvelope
from gcs_utm.model import FloatArray


def deformed(
    lp: LocalPlan,
    grid: FloatArray,
    d: FloatArray,
    axis: cd.Axis,
    sign: int,
    *,
    cruise_speed_mps: float,
    envelope: PerformanceEnvelope,
    max_speed_factor: float,
) -> LocalPlan:
    """The plan ``lp`` displaced by ``sign * d`` (on ``grid``) along ``axis``, re-timed. The
    displacement flown is :func:`concave_hull` of ``d``: out, along, back."""
    d = concave_hull(d)
    times = _kink_times(lp, grid, d)
    be, bn, bz = lp.coords(times)
    disp = sign * np.interp(times, grid, d)
    xe, xn, xz = be, bn, bz
    if axis is cd.Axis.VERTICAL:
        xz = bz + disp
    else:
        nx, ny = cd.left_normals_en(be, bn)
        xe = be + disp * nx
        xn = bn + disp * ny
    dt = times[1:] - times[:-1]
    safe_dt = np.maximum(dt, 1e-9)
    pace = np.hypot(be[1:] - be[:-1], bn[1:] - bn[:-1]) / safe_dt
    speed = np.minimum(
        np.maximum(cruise_speed_mps, pace) * max_speed_factor,
        np.maximum(envelope.max_speed_mps, pace),
    )
    dz_old = bz[1:] - bz[:-1]
    dz_new = xz[1:] - xz[:-1]
    up = np.maximum(envelope.climb_rate_mps, np.maximum(dz_old, 0.0) / safe_dt)
    down = np.maximum(envelope.descent_rate_mps, np.maximum(-dz_old, 0.0) / safe_dt)
    vertical = np.where(dz_new > 0.0, dz_new / up, -dz_new / down)
    need = np.maximum(
        dt, np.maximum(np.hypot(xe[1:] - xe[:-1], xn[1:] - xn[:-1]) / speed, vertical)
    )
    t = np.empty(len(times))
    t[0] = times[0]
    np.cumsum(need, out=t[1:])
    t[1:] += times[0]
    off = np.array([xe[-1] - lp.e[-1], xn[-1] - lp.n[-1], xz[-1] - lp.z[-1]])
    if float(np.abs(off).max()) > 1e-3:
        # The plan ended before the cord could ramp back: fly back to the filed final
        # waypoint (cruise speed, climb or descent rate) so the alternative keeps the
        # destination.
        rate = envelope.descent_rate_mps if off[2] > 0.0 else envelope.climb_rate_mps
        dt_back = max(float(np.hypot(off[0], off[1])) / cruise_speed_mps, abs(off[2]) / rate)
        xe = np.append(xe, lp.e[-1])
        xn = np.append(xn, lp.n[-1])
        xz = np.append(xz, lp.z[-1])
        t = np.append(t, t[-1] + dt_back)
    return LocalPlan(xe, xn, xz, t)


def concave_hull(d: FloatArray) -> FloatArray:
    """The least concave majorant of ``d`` (one value per cord step) over the span where it
    is not zero: out, along, back with as few corners as a profile at least ``d`` can have.
    A converged cord wanders (a dip between two conflicts, a staircase where a crossing
    UAS's demand moves along the cord), and every wiggle is two more corners a short leg
    apart: a multirotor slows down at each and falls metres behind its plan (time its
    mission's speeds never make up), a fixed wing cannot turn inside them. Concave, the hull
    is never steeper than ``d`` (its slopes are chords of ``d``), so it keeps the cord's
    slope limit, and never below it, so it keeps at least the separation the cord found
    (Monitoring verifies the plan either way)."""
    nz = np.flatnonzero(d > 1e-9)
    if d.shape[0] < 3 or nz.size == 0:
        return d
    a = max(int(nz[0]) - 1, 0)
    b = min(int(nz[-1]) + 1, d.shape[0] - 1)
    hull: list[int] = []  # upper hull of the points (k, d[k]), k in [a, b]
    for k in range(a, b + 1):
        while len(hull) >= 2:
            i0, i1 = hull[-2], hull[-1]
            # drop i1 when it lies on or below the chord i0 -> k
            if (d[i1] - d[i0]) * (k - i0) <= (d[k] - d[i0]) * (i1 - i0):
                hull.pop()
            else:
                break
        hull.append(k)
    out = d.copy()
    ks = np.arange(a, b + 1, dtype=np.float64)
    out[a : b + 1] = np.interp(ks, np.asarray(hull, dtype=np.float64), d[hull])
    return np.asarray(np.maximum(out, d), dtype=np.float64)


def _kink_times(lp: LocalPlan, grid: FloatArray, d: FloatArray) -> FloatArray:
    """The filed waypoint times and the grid times where the displacement's slope changes
    (inside the plan), sorted, without duplicates."""
    d1 = d[1:] - d[:-1]
    kinks = grid[1:-1][np.abs(d1[1:] - d1[:-1]) > 1e-9]
    inside = (kinks >= lp.t[0]) & (kinks <= lp.t[-1])
    times = np.concatenate((kinks[inside], lp.t))
    times.sort()
    if times.shape[0] > 1:
        times = times[np.concatenate(([True], times[1:] != times[:-1]))]
    return times
