"""Geofences a plan runs into, found when it is filed: which waypoint, and a proposed fix.

A plan whose path or destination lies inside an active geofence (grown by the operation's
volume, in space and time, as :func:`.strategic.plan_vs_geofences` tests it) would be flown
into the fence, or ended inside it and hovered there: Tactical Deconfliction can only take it
out again in flight. So at filing, each such fence gives one :class:`FenceFinding` naming the
operation, the fence and the waypoint (the destination first, then the first waypoint inside,
else the leg that enters it), with a fix: a waypoint inside moves to the nearest point
``FIX_MARGIN_M`` outside the grown fence; a leg that crosses it is rerouted around it; a fence
that ends is waited for. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs_utm.core.monitoring.fences import LocalFence, localise
from gcs_utm.core.monitoring.geometry import FloatArray, points_in_edges
from gcs_utm.core.monitoring.strategic import plan_local
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Geofence, GeofenceId, Operation, OperationId

FIX_MARGIN_M = 5.0
"""How far outside the grown fence a proposed waypoint lies."""


@dataclass(frozen=True, slots=True, kw_only=True)
class FenceFinding:
    """``waypoint`` of ``operation_id``'s plan lies inside ``geofence_id`` (``inside``), or
    the leg to it enters the fence; ``fix`` says what would clear it."""

    operation_id: OperationId
    plan_version: int
    geofence_id: GeofenceId
    waypoint: int
    destination: bool
    inside: bool
    entry_t_s: float
    fix: str

    def message(self) -> str:
        if self.inside:
            where = f"waypoint {self.waypoint}" + (" (the destination)" if self.destination else "")
            what = f"{where} lies inside active geofence {self.geofence_id}"
        else:
            what = (
                f"the leg from waypoint {self.waypoint - 1} to {self.waypoint} enters active "
                f"geofence {self.geofence_id}"
            )
        return (
            f"operation {self.operation_id} plan v{self.plan_version}: {what} (with its "
            f"operational volume, from t={self.entry_t_s:.1f}); fix: {self.fix}"
        )


def plan_in_fences(
    plan: FlightPlan, op: Operation, geofences: Sequence[Geofence], frame: LocalFrame
) -> list[FenceFinding]:
    """One finding per geofence that binds ``op`` and that ``plan`` enters, in the order of
    ``geofences`` (empty: the plan keeps its operational volume out of every fence)."""
    pts = plan_local(plan, frame)
    ov = op.operational_volume_m
    out: list[FenceFinding] = []
    for g in geofences:
        if not g.applies_to(op.id):
            continue
        f = localise(g, frame, ov)
        if not f.active_between(float(pts[0, 3]), float(pts[-1, 3])):
            continue
        found = _finding(pts, f)
        if found is None:
            continue
        k, inside, t = found
        out.append(
            FenceFinding(
                operation_id=op.id,
                plan_version=plan.version,
                geofence_id=g.id,
                waypoint=k,
                destination=inside and k == len(pts) - 1,
                inside=inside,
                entry_t_s=t,
                fix=_fix(pts, k, inside, f, g, frame, ov),
            )
        )
    return out


def _inside(pts: FloatArray, f: LocalFence) -> FloatArray:
    """Per waypoint: inside the grown fence's prism (space, band and window)?"""
    if f.center is not None:
        flat = np.hypot(pts[:, 0] - f.center[0], pts[:, 1] - f.center[1]) <= f.radius_m
    else:
        assert f.edges is not None
        flat = points_in_edges(pts[:, 0], pts[:, 1], f.edges)
    band = (pts[:, 2] >= f.z_lo) & (pts[:, 2] <= f.z_hi)
    window = (pts[:, 3] >= f.t_lo) & (pts[:, 3] <= f.t_hi)
    return np.asarray(flat & band & window)


def _finding(pts: FloatArray, f: LocalFence) -> tuple[int, bool, float] | None:
    """(waypoint, inside, time) of the fence's worst trace on the plan: the destination
    inside it, else the first waypoint inside, else the first leg that enters it."""
    inside = _inside(pts, f)
    if inside[-1]:
        return len(pts) - 1, True, float(pts[-1, 3])
    if inside.any():
        k = int(np.argmax(inside))
        return k, True, float(pts[k, 3])
    if len(pts) < 2:
        return None
    s = f.first_entry(pts[:-1], pts[1:])
    hit = np.flatnonzero(np.isfinite(s))
    if hit.size == 0:
        return None
    k = int(hit[0])
    return k + 1, False, float(pts[k, 3] + s[k] * (pts[k + 1, 3] - pts[k, 3]))


def _fix(  # noqa: PLR0917 - the finding's parts
    pts: FloatArray,
    k: int,
    inside: bool,
    f: LocalFence,
    g: Geofence,
    frame: LocalFrame,
    ov_m: float,
) -> str:
    later = f" or fly after the fence ends (t={f.t_hi:.0f})" if math.isfinite(f.t_hi) else ""
    if not inside:
        return f"reroute the leg around the fence, keeping the operational volume out{later}"
    e, n = _outside(pts[k, :2], f, g, frame, ov_m)
    lat, lon = frame.point_to_wgs84(e, n)
    d = float(np.hypot(e - pts[k, 0], n - pts[k, 1]))
    return (
        f"move waypoint {k} to {lat:.6f}, {lon:.6f} ({d:.0f} m away, outside geofence "
        f"{g.id} and its operational volume){later}"
    )


def _outside(
    p: FloatArray, f: LocalFence, g: Geofence, frame: LocalFrame, ov_m: float
) -> tuple[float, float]:
    """The nearest point ``FIX_MARGIN_M`` outside the fence grown by ``ov_m``."""
    if f.center is not None:
        d = np.array([p[0] - f.center[0], p[1] - f.center[1]])
        r = float(np.hypot(*d))
        u = d / r if r > 1e-9 else np.array([1.0, 0.0])
        q = np.array(f.center) + u * (f.radius_m + FIX_MARGIN_M)
        return float(q[0]), float(q[1])
    # imported here: only a polygon fence needs shapely (command start-up time)
    from shapely.geometry import Point, Polygon

    ex, ny = frame.to_local(
        np.array([v.lat_deg for v in g.vertices]), np.array([v.lon_deg for v in g.vertices])
    )
    grown = Polygon(np.column_stack([ex, ny])).buffer(ov_m + FIX_MARGIN_M)
    ring = grown.exterior
    q = ring.interpolate(ring.project(Point(float(p[0]), float(p[1]))))
    return float(q.x), float(q.y)
