"""Plan and geofence geometry in the airspace's local frame, shared by cords, A* and scoring.

Conventions: ``e``/``n`` are metres east/north in :class:`gcs_utm.geo.LocalFrame`, ``z`` is
``alt_amsl_m``, ``t`` is POSIX seconds. A :class:`LocalPlan` is the piecewise-linear 4D
trajectory through its waypoints; before its first and after its last time it does not exist
(sampling returns ``valid = False`` there), as Monitoring treats plans.

Obstacles are geofences inflated by a clearance (the operation's operational-volume radius
plus a margin) as *circumscribing* polygons: a cylinder becomes a regular polygon whose edges
are tangent-or-outside the inflated circle, a polygon is buffered with mitred joins (mitre
corners lie outside the round buffer). So a path outside an obstacle polygon is at least the
clearance away from the geofence; the A* graph nodes sit a further ``NODE_EPS_M`` outside.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import MultiPolygon, Point, Polygon
from shapely.ops import unary_union

from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, FloatArray, Geofence, GeofenceId, GeofenceShape, Waypoint4D

NODE_EPS_M = 0.5
"""Graph nodes lie this far outside the obstacle polygons, so that an edge along an obstacle
border does not touch it (numerical safety, well below any clearance)."""


@dataclass(frozen=True, slots=True, eq=False)
class LocalPlan:
    """Waypoints of one plan in the local frame: four equal-length float arrays."""

    e: FloatArray
    n: FloatArray
    z: FloatArray
    t: FloatArray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def xyz(self) -> FloatArray:
        out = np.empty((self.t.shape[0], 3))
        out[:, 0] = self.e
        out[:, 1] = self.n
        out[:, 2] = self.z
        return out

    def sample(self, times: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
        """Positions (len(times), 3) and a validity mask at ``times``."""
        if len(self) == 1:
            pos = np.repeat(self.xyz(), times.shape[0], axis=0)
            return pos, np.isclose(times, self.t[0])
        pos = np.empty((times.shape[0], 3))
        pos[:, 0] = np.interp(times, self.t, self.e)
        pos[:, 1] = np.interp(times, self.t, self.n)
        pos[:, 2] = np.interp(times, self.t, self.z)
        valid = (times >= self.t[0] - 1e-9) & (times <= self.t[-1] + 1e-9)
        return pos, valid

    def coords(self, times: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The positions of :meth:`sample` as one array per coordinate (e, n, z), without
        the validity mask."""
        if len(self) == 1:
            k = times.shape[0]
            return np.full(k, self.e[0]), np.full(k, self.n[0]), np.full(k, self.z[0])
        return (
            np.interp(times, self.t, self.e),
            np.interp(times, self.t, self.n),
            np.interp(times, self.t, self.z),
        )

    def position_at(self, t_s: float) -> FloatArray:
        pos, _ = self.sample(np.array([t_s]))
        return np.asarray(pos[0], dtype=np.float64)

    def length_m(self, from_t_s: float | None = None) -> float:
        """3D path length, from ``from_t_s`` when given."""
        lp = self if from_t_s is None else self.after(from_t_s)
        xyz = lp.xyz()
        d = xyz[1:] - xyz[:-1]
        return float(np.sqrt((d * d).sum(axis=1)).sum())

    def after(self, t_s: float) -> LocalPlan:
        """The part of the plan from ``t_s`` on (starting with the interpolated point)."""
        if t_s <= self.t[0]:
            return self
        if t_s >= self.t[-1]:
            p = self.xyz()[-1]
            return LocalPlan(*(np.array([v]) for v in (p[0], p[1], p[2], self.t[-1])))
        keep = self.t > t_s
        p = self.position_at(t_s)
        return LocalPlan(
            np.concatenate([[p[0]], self.e[keep]]),
            np.concatenate([[p[1]], self.n[keep]]),
            np.concatenate([[p[2]], self.z[keep]]),
            np.concatenate([[t_s], self.t[keep]]),
        )


SCREEN_STEP_S = 0.5
"""Sample step of :func:`separation_screen`: at UAS speeds the bound's slack (relative speed x
half a step) stays a few metres, below the separation margin the cords keep."""

SCREEN_TOLERANCE_M = 0.01
"""Slack for the WGS84 round trip of a plan (far below a millimetre in practice)."""


def linspace(start: float, stop: float, num: int) -> FloatArray:
    """``np.linspace(start, stop, num)`` for num >= 2, by the same arithmetic (index times
    step, plus start; the last value is the stop) without its argument handling."""
    out = np.arange(num, dtype=np.float64) * ((stop - start) / (num - 1)) + start
    out[-1] = stop
    return out


def max_speeds(lp: LocalPlan) -> tuple[float, float]:
    """Largest horizontal and vertical speed (m/s) over the plan's segments; inf when a
    segment moves in zero time."""
    if len(lp) < 2:
        return 0.0, 0.0
    e, n, z, t = lp.e, lp.n, lp.z, lp.t
    dt = t[1:] - t[:-1]
    dh = np.hypot(e[1:] - e[:-1], n[1:] - n[:-1])
    dz = np.abs(z[1:] - z[:-1])
    with np.errstate(divide="ignore", invalid="ignore"):
        vh = np.where(dh > 0.0, dh / dt, 0.0)
        vz = np.where(dz > 0.0, dz / dt, 0.0)
    return float(vh.max()), float(vz.max())


def separation_screen(
    a: LocalPlan,
    b: LocalPlan,
    h_min_m: float,
    v_min_m: float,
    *,
    spherical: bool,
    speeds_a: tuple[float, float] | None = None,
    speeds_b: tuple[float, float] | None = None,
) -> tuple[bool, bool]:
    """(broken, clear) for two plans over the time both exist, from samples every
    ``SCREEN_STEP_S`` at most. ``broken``: a sampled instant already violates the minima, so
    the exact check would flag the pair. ``clear``: no instant can violate them, since the
    relative position moves at most (sum of the two plans' max speeds) x half a step away
    from the nearest sample. Neither: only the exact check can tell."""
    t0, t1 = max(float(a.t[0]), float(b.t[0])), min(float(a.t[-1]), float(b.t[-1]))
    if t1 < t0:
        return False, True
    n = max(2, math.ceil((t1 - t0) / SCREEN_STEP_S) + 1)
    t = linspace(t0, t1, n)
    half = 0.5 * (t1 - t0) / (n - 1)  # s: every instant is this close to a sample
    ae, an, az = a.coords(t)
    be, bn, bz = b.coords(t)
    dh = np.hypot(ae - be, an - bn)
    dv = np.abs(az - bz)
    vha, vza = speeds_a if speeds_a is not None else max_speeds(a)
    vhb, vzb = speeds_b if speeds_b is not None else max_speeds(b)
    slack_h = (vha + vhb) * half + SCREEN_TOLERANCE_M
    slack_v = (vza + vzb) * half + SCREEN_TOLERANCE_M
    if spherical:
        d3 = np.hypot(dh, dv)
        broken = bool((d3 < h_min_m - SCREEN_TOLERANCE_M).any())
        clear = bool((d3 - math.hypot(slack_h, slack_v) >= h_min_m).all())
    else:
        tol = SCREEN_TOLERANCE_M
        broken = bool(((dh < h_min_m - tol) & (dv < v_min_m - tol)).any())
        clear = bool(((dh - slack_h >= h_min_m) | (dv - slack_v >= v_min_m)).all())
    return broken, clear


def plan_to_local(plan: FlightPlan, frame: LocalFrame) -> LocalPlan:
    lat = np.array([w.lat_deg for w in plan.waypoints])
    lon = np.array([w.lon_deg for w in plan.waypoints])
    e, n = frame.to_local(lat, lon)
    z = np.array([w.alt_amsl_m for w in plan.waypoints], dtype=np.float64)
    t = np.array([w.t_s for w in plan.waypoints], dtype=np.float64)
    return LocalPlan(np.atleast_1d(e), np.atleast_1d(n), z, t)


def local_to_plan(
    lp: LocalPlan, base: FlightPlan, frame: LocalFrame, *, created_t_s: float, reason: str
) -> FlightPlan:
    """A new version of ``base`` through the points of ``lp``."""
    return local_to_plans([lp], [base], frame, created_t_s=created_t_s, reasons=[reason])[0]


def local_to_plans(
    lps: Sequence[LocalPlan],
    bases: Sequence[FlightPlan],
    frame: LocalFrame,
    *,
    created_t_s: float,
    reasons: Sequence[str],
) -> list[FlightPlan]:
    """New versions of ``bases[i]`` through the points of ``lps[i]``: one frame conversion for
    all of them (the projection is point by point, so each plan gets exactly the values a
    conversion of its own would give)."""
    if not lps:
        return []
    lat, lon = frame.to_wgs84(
        np.concatenate([lp.e for lp in lps]), np.concatenate([lp.n for lp in lps])
    )
    lat = np.atleast_1d(lat)
    lon = np.atleast_1d(lon)
    z = np.concatenate([lp.z for lp in lps])
    t = np.concatenate([lp.t for lp in lps])
    # Every value passed the checks Waypoint4D.__post_init__ makes (finite, latitude and
    # longitude in range), all at once: build the waypoints without repeating them per point
    # (one Position and one LatLon each). Otherwise the per-point constructor raises the error
    # naming the bad value.
    trusted = _valid_waypoints(lat, lon, z, t)
    cols = (lat.tolist(), lon.tolist(), z.tolist(), t.tolist())
    out = []
    k = 0
    for lp, base, reason in zip(lps, bases, reasons, strict=True):
        m = len(lp)
        rows = zip(*(c[k : k + m] for c in cols), strict=True)
        k += m
        if trusted:
            wps = tuple(_trusted_waypoint(*w) for w in rows)
        else:
            wps = tuple(
                Waypoint4D(lat_deg=a, lon_deg=o, alt_amsl_m=h, t_s=s) for a, o, h, s in rows
            )
        out.append(
            FlightPlan(
                operation_id=base.operation_id,
                version=base.version + 1,
                waypoints=wps,
                created_t_s=created_t_s,
                reason=reason,
            )
        )
    return out


def _valid_waypoints(lat: FloatArray, lon: FloatArray, z: FloatArray, t: FloatArray) -> bool:
    """The checks of ``Waypoint4D`` (and its ``Position``/``LatLon``) on whole columns."""
    return bool(
        np.isfinite(z).all()
        and np.isfinite(t).all()
        and ((lat >= -90.0) & (lat <= 90.0)).all()  # NaN fails the comparisons
        and ((lon >= -180.0) & (lon <= 180.0)).all()
    )


_SET = object.__setattr__


def _trusted_waypoint(lat: float, lon: float, alt: float, t: float) -> Waypoint4D:
    """A Waypoint4D from values already validated by :func:`_valid_waypoints`."""
    w: Waypoint4D = object.__new__(Waypoint4D)
    _SET(w, "lat_deg", lat)
    _SET(w, "lon_deg", lon)
    _SET(w, "alt_amsl_m", alt)
    _SET(w, "t_s", t)
    return w


@dataclass(frozen=True, slots=True, eq=False)
class LocalFence:
    """A geofence in the local frame: its exact 2D shape and its altitude/time window."""

    id: GeofenceId
    shape: Polygon
    cylinder: tuple[float, float, float] | None  # (e, n, radius_m) when a cylinder
    min_alt_amsl_m: float
    max_alt_amsl_m: float
    start_t_s: float | None
    end_t_s: float | None

    def active_between(self, t0_s: float, t1_s: float) -> bool:
        if self.start_t_s is not None and t1_s < self.start_t_s:
            return False
        return not (self.end_t_s is not None and t0_s > self.end_t_s)

    def active_mask(self, t: FloatArray) -> npt.NDArray[np.bool_]:
        m = np.ones(t.shape, dtype=bool)
        if self.start_t_s is not None:
            m &= t >= self.start_t_s
        if self.end_t_s is not None:
            m &= t <= self.end_t_s
        return m

    def horizontal_distance(self, e: FloatArray, n: FloatArray) -> FloatArray:
        """Signed horizontal distance to the border: negative inside."""
        if self.cylinder is not None:
            ce, cn, r = self.cylinder
            return np.asarray(np.hypot(e - ce, n - cn) - r, dtype=np.float64)
        pts = shapely.points(e, n)
        d = shapely.distance(self.shape.exterior, pts)
        inside = shapely.contains_xy(self.shape, e, n)
        return np.asarray(np.where(inside, -d, d), dtype=np.float64)

    def inflated(self, clearance_m: float, sides: int) -> Polygon:
        """The obstacle polygon: every point outside it is >= clearance_m from the fence."""
        if self.cylinder is not None:
            ce, cn, r = self.cylinder
            rc = (r + clearance_m) / math.cos(math.pi / sides)
            a = np.arange(sides) * 2.0 * math.pi / sides
            return Polygon(np.column_stack([ce + rc * np.cos(a), cn + rc * np.sin(a)]))
        if clearance_m <= 0.0:
            return self.shape
        return self.shape.buffer(clearance_m, join_style="mitre", mitre_limit=2.0)


def fence_to_local(g: Geofence, frame: LocalFrame) -> LocalFence:
    if g.shape is GeofenceShape.CYLINDER:
        assert g.center is not None and g.radius_m is not None  # checked by Geofence
        ce, cn = frame.point_to_local(g.center.lat_deg, g.center.lon_deg)
        shape = Point(ce, cn).buffer(g.radius_m, quad_segs=16)
        cyl: tuple[float, float, float] | None = (ce, cn, g.radius_m)
    else:
        lat = np.array([v.lat_deg for v in g.vertices])
        lon = np.array([v.lon_deg for v in g.vertices])
        e, n = frame.to_local(lat, lon)
        shape = Polygon(np.column_stack([e, n]))
        if not shape.is_valid:
            shape = shapely.make_valid(shape).convex_hull
        cyl = None
    return LocalFence(
        id=g.id,
        shape=shape,
        cylinder=cyl,
        min_alt_amsl_m=g.min_alt_amsl_m,
        max_alt_amsl_m=g.max_alt_amsl_m,
        start_t_s=g.start_t_s,
        end_t_s=g.end_t_s,
    )


def relevant_fences(
    fences: Iterable[LocalFence], t0_s: float, t1_s: float, z_lo: float, z_hi: float
) -> list[LocalFence]:
    """Fences active some time in [t0, t1] whose band overlaps [z_lo, z_hi]."""
    return [
        f
        for f in fences
        if f.active_between(t0_s, t1_s) and f.min_alt_amsl_m <= z_hi and f.max_alt_amsl_m >= z_lo
    ]


def merged_obstacles(fences: Sequence[LocalFence], clearance_m: float, sides: int) -> list[Polygon]:
    """Inflated fences, overlapping ones merged, holes filled (an enclosed pocket is not a
    place to route through)."""
    if not fences:
        return []
    polys = [f.inflated(clearance_m, sides) for f in fences]
    merged = unary_union(polys) if len(polys) > 1 else polys[0]
    parts = list(merged.geoms) if isinstance(merged, MultiPolygon) else [merged]
    return [Polygon(p.exterior) for p in parts if isinstance(p, Polygon) and not p.is_empty]
