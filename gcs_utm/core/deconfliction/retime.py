"""Plans as they are being flown: each operation's remaining plan re-timed by its current delay.

Monitoring predicts from the tracks (a UAS that started 3 s late is predicted 3 s behind its
plan), so Tactical Deconfliction and the joint selection must reason on the same timing, or
"keep the plan" would look conflict-free while the UAS is on its way into a loss of
separation (the paper's use case 1). For every operation with a fresh track close to its plan,
the plan is cut at the track's projection on it and the rest is shifted by
``delay = t_track - t_plan(projection)``. Operations without a usable track keep their plan.
A hold (two waypoints at one place) is at every time of its window: a UAS holding there is
at the plan time nearest its own, so a UAS holding as planned keeps its plan's timing.

Pure: time comes from the snapshot; positions go through the airspace frame.
"""

from __future__ import annotations

import dataclasses
import math

from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Operation,
    OperationId,
    Track,
    TrackId,
    Waypoint4D,
)


def _project(frame: LocalFrame, plan: FlightPlan, track: Track) -> tuple[int, float, float] | None:
    """(segment index, fraction along it, 3D distance) of the track's closest point on the
    plan; among segments within 1.5x the best distance, the one whose time window is closest
    to the track's time wins (loops and lawn-mower rows pass the same place twice)."""
    wps = plan.waypoints
    if len(wps) < 2:
        return None
    pts = []
    for w in wps:
        e, n = frame.point_to_local(w.lat_deg, w.lon_deg)
        pts.append((e, n, w.alt_amsl_m))
    p = (track.east_m, track.north_m, track.alt_amsl_m)
    cands: list[tuple[float, int, float]] = []
    for i in range(len(pts) - 1):
        a, b = pts[i], pts[i + 1]
        d = [b[k] - a[k] for k in range(3)]
        seg2 = sum(x * x for x in d)
        if seg2 == 0.0:
            # a hold is at every time of its window: the track is at the nearest one
            dt = wps[i + 1].t_s - wps[i].t_s
            u = (track.t_s - wps[i].t_s) / dt if dt > 0.0 else 0.0
        else:
            u = sum((p[k] - a[k]) * d[k] for k in range(3)) / seg2
        u = min(1.0, max(0.0, u))
        q = [a[k] + u * d[k] for k in range(3)]
        cands.append((math.dist(p, q), i, u))
    best = min(c[0] for c in cands)
    near = [c for c in cands if c[0] <= 1.5 * best + 1.0]

    def time_gap(c: tuple[float, int, float]) -> float:
        t = wps[c[1]].t_s + c[2] * (wps[c[1] + 1].t_s - wps[c[1]].t_s)
        return abs(t - track.t_s)

    dist, i, u = min(near, key=time_gap)
    return i, u, dist


def retime_plan(
    frame: LocalFrame, op: Operation, track: Track, *, max_offset_m: float
) -> FlightPlan | None:
    """The rest of ``op``'s plan from the track's position, shifted by its delay; None when the
    track is further than ``max_offset_m`` from the plan or the plan is already flown."""
    plan = op.plan
    hit = _project(frame, plan, track)
    if hit is None:
        return None
    i, u, dist = hit
    if dist > max_offset_m:
        return None
    a, b = plan.waypoints[i], plan.waypoints[i + 1]
    t_plan = a.t_s + u * (b.t_s - a.t_s)
    delay = track.t_s - t_plan
    start = Waypoint4D(
        lat_deg=a.lat_deg + u * (b.lat_deg - a.lat_deg),
        lon_deg=a.lon_deg + u * (b.lon_deg - a.lon_deg),
        alt_amsl_m=a.alt_amsl_m + u * (b.alt_amsl_m - a.alt_amsl_m),
        t_s=track.t_s,
    )
    rest = [dataclasses.replace(w, t_s=w.t_s + delay) for w in plan.waypoints[i + 1 :]]
    if not rest:
        return None
    if rest[0].t_s < start.t_s:  # rounding at a vertex: keep times monotonic
        rest[0] = dataclasses.replace(rest[0], t_s=start.t_s)
    return dataclasses.replace(plan, waypoints=(start, *rest))


def retime_snapshot(
    snapshot: AirspaceSnapshot, frame: LocalFrame, *, offset_factor: float = 1.0
) -> AirspaceSnapshot:
    """``snapshot`` with every tracked operation's plan replaced by its re-timed remainder.
    A track counts when it is fresh and within ``offset_factor`` x the operational volume of
    its plan."""
    ops: dict[OperationId, Operation] = {}
    for op_id, op in snapshot.operations.items():
        track = snapshot.tracks.get(TrackId(op_id))
        new_plan = None
        if track is not None and not track.stale:
            new_plan = retime_plan(
                frame, op, track, max_offset_m=offset_factor * op.operational_volume_m
            )
        ops[op_id] = op if new_plan is None else dataclasses.replace(op, plan=new_plan)
    return dataclasses.replace(snapshot, operations=ops)
