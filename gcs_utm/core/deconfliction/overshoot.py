"""Overshoot of a multirotor's turns next to a geofence.

A multirotor does not turn on a point: at a turn by an angle a it brakes the part of its
forward speed v that the next leg does not keep, v min(1, 1 - cos a) (all of it from a right
angle on), and flies on meanwhile (a 150 degree reversal 3 m from a fence edge at 10 m/s was
flown 0.5-0.9 m inside). So a candidate plan of Tactical Deconfliction is dropped (with the
reason) when, at one of its turns sharper than ``MIN_TURN_DEG``, the straight line on along
the incoming leg for the distance that braking takes at the vehicle's acceleration (its
stopping distance, :meth:`~gcs_utm.envelope.PerformanceEnvelope.stopping_distance_m`, at
that reduced speed) comes closer than the operational volume to a geofence whose altitude
band (grown by the volume) and activation window hold the turn: the turn point must be that
far from the fence's volume in the direction the vehicle flies. Checked at every generated
waypoint and at the start point, where the vehicle turns from the way it flies now (its
filed plan as flown) onto the first leg. A plan that leaves a fence it is in (escape, hold
outside, home or a landing site from inside) is judged from its exit point on, as it is
verified: braking on the way out is unavoidable, and judging it would leave the UAS with no
way out offered. A turn point within the volume of a fence is not judged either. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalFence, LocalPlan
from gcs_utm.model import FloatArray, Geofence, Operation

MIN_TURN_DEG = 30.0
"""Gentler turns are flown through at speed: nothing to brake."""
SAMPLE_M = 1.0
"""Spacing of the points checked along an overshoot."""
SAME_POINT_M = 0.05
"""A generated point this close to a filed waypoint is that waypoint."""


def _turns(pts: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per interior point of the polyline ``pts`` (K, 3) timed ``t``: the turn angle (rad,
    nan where a leg around it does not move horizontally), the incoming unit heading (K-2, 2)
    and the incoming horizontal speed (m/s)."""
    d = np.diff(pts[:, :2], axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    dt = np.maximum(np.diff(t), 1e-9)
    moving = length > SAME_POINT_M
    safe = np.where(moving, length, 1.0)
    u = d / safe[:, None]
    cos = np.clip((u[:-1] * u[1:]).sum(axis=1), -1.0, 1.0)
    turn = np.where(moving[:-1] & moving[1:], np.arccos(cos), np.nan)
    return turn, u[:-1], length[:-1] / dt[:-1]


def overshoot_flags(  # noqa: PLR0917 - the candidate's parts, as td._check has them
    full: LocalPlan,
    start_t_s: float,
    filed: LocalPlan,
    fences: Sequence[LocalFence],
    geofences: Sequence[Geofence],
    op: Operation,
) -> list[str]:
    """Turns of ``full`` (a new plan of ``op`` with its lead-in) from ``start_t_s`` on whose
    overshoot comes within the operational volume of one of ``fences`` (the local forms of
    ``geofences``, those that bind ``op``); empty when none does or the vehicle cannot hover.
    ``filed`` is the UAS's filed plan: where it comes from before the new plan's first point,
    and which waypoints were not generated."""
    envelope = op.performance()
    ov_m = op.operational_volume_m
    applies = [g.applies_to(op.id) for g in geofences]
    if not envelope.can_hover or len(full) < 2 or not any(applies):
        return []
    t_before = float(full.t[0]) - 1.0
    pts = np.vstack([filed.position_at(t_before), full.xyz()])
    t = np.concatenate([[t_before], full.t])
    turn, heading, speed = _turns(pts, t)
    at = np.arange(1, len(pts) - 1)  # index in pts of each turn point
    start = int(np.searchsorted(t, start_t_s - 1e-6))
    judged = (at >= start) & (np.nan_to_num(turn) > math.radians(MIN_TURN_DEG))
    if judged.any() and filed.e.size:
        gap = np.linalg.norm(pts[at][:, None, :] - filed.xyz()[None, :, :], axis=2).min(axis=1)
        judged &= (gap > SAME_POINT_M) | (at == start)
    if not judged.any():
        return []
    boxes = np.array([f.shape.bounds for f in fences])  # east_min, north_min, east_max, north_max
    binds = np.array(applies, dtype=bool)
    out: list[str] = []
    for k in np.flatnonzero(judged):
        v = min(float(speed[k]), envelope.max_speed_mps)
        reach = envelope.stopping_distance_m(v * min(1.0, 1.0 - math.cos(float(turn[k]))))
        p = pts[at[k]]
        s = np.linspace(0.0, reach, max(2, math.ceil(reach / SAMPLE_M) + 1))
        line = p[:2] + s[:, None] * heading[k]
        lo, hi = line.min(axis=0) - ov_m, line.max(axis=0) + ov_m
        # a fence whose box is farther than the volume from the overshoot cannot matter
        near = binds & (boxes[:, 0] <= hi[0]) & (boxes[:, 2] >= lo[0])
        near &= (boxes[:, 1] <= hi[1]) & (boxes[:, 3] >= lo[1])
        for i in np.flatnonzero(near):
            f = fences[int(i)]
            if not _holds(f, float(p[2]), float(t[at[k]]), ov_m):
                continue
            dist = f.horizontal_distance(line[:, 0], line[:, 1])
            if dist[0] >= ov_m and float(dist.min()) < ov_m:
                out.append(
                    f"turn of {math.degrees(float(turn[k])):.0f} deg at waypoint "
                    f"{int(at[k]) - 1} overshoots {reach:.1f} m at {v:.1f} m/s, to "
                    f"{float(dist.min()):.1f} m from geofence {f.id} (volume {ov_m:.1f} m)"
                )
                break
    return out


def _holds(f: LocalFence, z: float, t: float, ov_m: float) -> bool:
    """Does the fence, its band grown by the volume, hold altitude ``z`` at time ``t``?"""
    if not f.active_between(t, t):
        return False
    return f.min_alt_amsl_m - ov_m <= z <= f.max_alt_amsl_m + ov_m
