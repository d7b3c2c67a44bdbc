"""The circle a fixed wing flies round its last waypoint once its plan has ended, against
geofences.

A fixed wing cannot stop: at its plan's end it circles the last waypoint at its turn radius
(:mod:`gcs_utm.core.tracking.loiter`). Monitoring predicts that circle only once the plan
has ended (before, the prediction stays at the last waypoint), so a fence beside the end
point was first predicted a few seconds before the circle reached it: a fence 52 m from the
end, entered on the 80 m circle 5 s after the end (``enc_7_0003_endpoint_vertical``), with
no time left for a new plan. Where on the circle the aircraft will be at a given time is
not known that far ahead (it depends on how it arrives), so the whole circle is checked, not
one predicted phase: :func:`end_ring` gives it as a closed polyline timed from the end over
one turn at the last leg's speed, :func:`ring_entry` its first entry into a fence.

The aircraft reaches the last waypoint, the circle's centre, along its last leg and turns
onto the circle on its own turn radius: that entry swings out to about two turn radii from
the centre on the side it turns to, ahead of the last leg, before it settles on the circle
(an end point 114 m from a fence, circled at 80 m, entered it 6 s after the plan's end,
``enc_3_0443_endpoint_vertical``). :func:`end_ring` begins with that entry
(:mod:`gcs_utm.core.tracking.loiter_entry`; started at the last waypoint and a tracking
error before and after it along the leg) and goes on round the circle from where it settles.

Used twice, so that what Monitoring flags TD does not propose again: Monitoring's cycle
(:func:`end_circle_hits`: operations whose plan ends inside the horizon and whose
prediction reaches the end point, against the fences as they are) and
:func:`.strategic.plan_vs_geofences` (a plan's circle against the fences as they are, while
its path keeps the operational volume from them). Pure.

Units: local frame metres (east, north, alt AMSL), seconds.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence

import numpy as np

from gcs_utm.core.monitoring.fences import LocalFence
from gcs_utm.core.monitoring.geometry import FloatArray
from gcs_utm.core.tracking import loiter_entry
from gcs_utm.model import Operation, OperationId

RING_POINTS = 36
"""Vertices of the circle's polyline (every 10 degrees: the chord's sagitta is 0.4 % of the
radius, 0.3 m on 80 m)."""

ENTRY_STEP_S = 1.0
"""Spacing in time of the entry's points (under 25 m at a fixed wing's speed, on a turn of
at least 37 m radius: within 2 m of the arc)."""

REACH_RADII = 2.0
"""A prediction whose point at the plan's end lies within this many radii of the last
waypoint is on its way to the circle (as :data:`.loiter.CAPTURE_RADII` of the tracker)."""


def loiter_radius_m(op: Operation) -> float:
    """The loiter radius a vehicle that cannot hover circles at (its turn radius), else 0."""
    env = op.performance()
    return 0.0 if env.can_hover else env.turn_radius_m


def circle_radius_m(op: Operation) -> float:
    """The radius of the circle checked round the last waypoint after the plan: for a
    vehicle that cannot hover its turn radius (the loiter radius it is set to) plus its
    tracking error (the autopilots fly wide of it: ArduPlane 81-96 m from the centre at
    80 m, docs/monitoring.md "Loiter ring"; the simulated plane about 88 m at 19 m/s), else
    0."""
    env = op.performance()
    return 0.0 if env.can_hover else env.turn_radius_m + env.tracking_tolerance_m()


def end_ring(
    plan_pts: FloatArray, radius_m: float, loiter_radius_m: float | None = None
) -> FloatArray | None:
    """(M, 4) east, north, alt, t: the entry onto the circle round the last point of
    ``plan_pts`` (K, 4) then the closed circle of ``radius_m`` from where the entry ends, at
    the last point's altitude, clockwise, timed from the end at the speed of the last leg
    with a horizontal length (None when the plan never moves horizontally). The entry is the
    capture of the circle of ``loiter_radius_m`` (the one the autopilot flies; default
    ``radius_m``) on that leg's course, from the last point and from that point moved along
    the leg by ``radius_m - loiter_radius_m`` (the tracking error) both ways, one after the
    other (the first the one started furthest along)."""
    if radius_m <= 0.0 or len(plan_pts) < 2:
        return None
    end = plan_pts[-1]
    # The last leg with a horizontal length (a plan may end with a hold at its last point).
    moved = np.flatnonzero(np.hypot(*(plan_pts[:-1, :2] - end[:2]).T) > 1e-6)
    if not len(moved):
        return None
    before = plan_pts[int(moved[-1])]
    d_e, d_n = float(end[0] - before[0]), float(end[1] - before[1])
    dt_s = float(plan_pts[int(moved[-1]) + 1, 3] - before[3])
    length_m = math.hypot(d_e, d_n)
    if dt_s <= 0.0:
        return None
    speed = length_m / dt_s  # m/s
    # The entry from where the aircraft may start it: the last point, and that point moved
    # along the leg by the tracking error, both ways (it reaches the point early or late).
    loiter_m = radius_m if loiter_radius_m is None else loiter_radius_m
    shift_m = max(radius_m - loiter_m, 0.0)
    u_e, u_n = d_e / length_m, d_n / length_m
    course = math.atan2(d_e, d_n)
    shifts = (shift_m, 0.0, -shift_m) if shift_m > 0.0 else (0.0,)
    starts = end[None, :2] + np.outer(shifts, [u_e, u_n])
    entries = _entries(starts, end, course, speed, loiter_m)
    entry = entries.reshape(-1, 4)
    last = entries[len(shifts) // 2, -1]  # the entry started at the last point
    bearing0 = math.atan2(float(last[0] - end[0]), float(last[1] - end[1]))
    turn = np.linspace(0.0, 2.0 * math.pi, RING_POINTS + 1)
    bearing = bearing0 + turn  # clockwise: bearing increasing
    ring = np.empty((RING_POINTS + 1, 4))
    ring[:, 0] = end[0] + radius_m * np.sin(bearing)
    ring[:, 1] = end[1] + radius_m * np.cos(bearing)
    ring[:, 2] = end[2]
    ring[:, 3] = float(last[3]) + radius_m * turn / speed  # round from where the entry ends
    return np.concatenate([entry, ring])


def _entries(
    starts_en: FloatArray, center: FloatArray, course_rad: float, speed_mps: float, loiter_m: float
) -> FloatArray:
    """(S, J, 4) the captures of the circle of ``loiter_m`` round ``center`` (east, north,
    alt, t: the last point) from each of ``starts_en`` (S, 2) on ``course_rad``, over one
    turn of the circle at ``speed_mps``, at the centre's altitude, timed from the centre's
    time."""
    n = len(starts_en)
    turn_s = 2.0 * math.pi * max(loiter_m, 1.0) / speed_mps
    tau = np.arange(0.0, turn_s + ENTRY_STEP_S, ENTRY_STEP_S)
    speed = np.full(n, speed_mps)
    east, north = loiter_entry.capture_points(
        center_en=np.repeat(center[None, :2], n, axis=0),
        radius_m=np.full(n, loiter_m),
        turn_radius_m=loiter_entry.capture_turn_radius_m(speed),
        clockwise=np.ones(n, dtype=bool),
        pos_en=starts_en,
        course_rad=np.full(n, course_rad),
        speed_mps=speed,
        tau_s=np.repeat(tau[None, :], n, axis=0),
        step_s=ENTRY_STEP_S / 2.0,
    )
    out = np.empty((n, len(tau), 4))
    out[:, :, 0] = east
    out[:, :, 1] = north
    out[:, :, 2] = center[2]
    out[:, :, 3] = center[3] + tau
    return out


def ring_entry(ring: FloatArray, fence: LocalFence) -> float | None:
    """The first time the closed ``ring`` (from :func:`end_ring`) is inside ``fence``, or
    None."""
    if not fence.active_between(float(ring[0, 3]), float(ring[-1, 3])):
        return None
    bx = fence.bbox
    lo, hi = ring[:, :2].min(axis=0), ring[:, :2].max(axis=0)
    if lo[0] > bx[2] or lo[1] > bx[3] or hi[0] < bx[0] or hi[1] < bx[1]:
        return None
    s = fence.first_entry(ring[:-1], ring[1:])
    hit = np.flatnonzero(np.isfinite(s))
    if not len(hit):
        return None
    k = int(hit[0])
    return float(ring[k, 3] + float(s[k]) * (ring[k + 1, 3] - ring[k, 3]))


class EndRings:
    """Each operation's :func:`end_ring`, kept while its plan stays: the ring depends only on
    the plan's points and the radii, and Monitoring checks it every cycle of the plan's last
    horizon (an integration of the entry each time, before). Keyed on the operation, hit
    only for the same points array (the caller's projection of one plan object: a new plan
    is a new array) and the same radii; one entry per operation, :meth:`prune` drops the
    operations gone."""

    def __init__(self) -> None:
        self._rings: dict[OperationId, tuple[FloatArray, float, float, FloatArray | None]] = {}

    def ring(
        self, op_id: OperationId, plan_pts: FloatArray, radius_m: float, loiter_radius_m: float
    ) -> FloatArray | None:
        """:func:`end_ring` of ``plan_pts`` (kept by the caller, not modified), cached."""
        hit = self._rings.get(op_id)
        if hit is not None and hit[0] is plan_pts and hit[1:3] == (radius_m, loiter_radius_m):
            return hit[3]
        ring = end_ring(plan_pts, radius_m, loiter_radius_m)
        if ring is not None:
            ring.setflags(write=False)  # shared by every cycle: never changed in place
        self._rings[op_id] = (plan_pts, radius_m, loiter_radius_m, ring)
        return ring

    def prune(self, current: Collection[OperationId]) -> None:
        """Drop the rings of operations not in ``current``."""
        for key in [k for k in self._rings if k not in current]:
            del self._rings[key]

    def __len__(self) -> int:
        return len(self._rings)


def end_circle_hits(
    *,
    ops: Sequence[Operation],
    plans: Sequence[FloatArray],
    predicted: FloatArray,
    fences: Sequence[LocalFence],
    t_s: float,
    rings: EndRings | None = None,
) -> list[tuple[int, LocalFence, float]]:
    """(index into ``ops``, fence, entry time) for each operation whose plan ends inside the
    predicted window and whose circle round the end point enters a fence inside it. ``plans`` (each
    (K, 4), local) are the operations' plans, ``predicted`` (N, S, 4) their predicted points
    (one row per operation, same order), ``t_s`` the cycle's time; ``rings`` keeps the rings
    from one call to the next (None: each computed)."""
    out: list[tuple[int, LocalFence, float]] = []
    for i, op in enumerate(ops):
        radius_m = circle_radius_m(op)
        pts = plans[i]
        if radius_m <= 0.0 or len(pts) < 2:
            continue
        end_t = float(pts[-1, 3])
        row = predicted[i]
        if not (t_s < end_t <= float(row[-1, 3])):
            continue
        k = int(np.searchsorted(row[:, 3], end_t, side="right")) - 1
        if math.hypot(*(row[k, :2] - pts[-1, :2])) > REACH_RADII * radius_m:
            continue  # the prediction does not reach the end point: sent elsewhere
        loiter_m = loiter_radius_m(op)
        if rings is None:
            ring = end_ring(pts, radius_m, loiter_m)
        else:
            ring = rings.ring(op.id, pts, radius_m, loiter_m)
        if ring is None:
            continue
        for f in fences:
            t = ring_entry(ring, f)
            if t is not None and t <= float(row[-1, 3]):  # inside the horizon, as the rest
                out.append((i, f, t))
    return out
