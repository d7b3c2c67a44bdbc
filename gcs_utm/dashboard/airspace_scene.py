"""The airspace map's view model: what the map draws, in local metres, built from one
:class:`~gcs_utm.dashboard.view.DashboardData` snapshot.

Everything the dashboard knows in WGS84 (tracks, filed plans, geofences) is put in one local
east/north frame in metres around the centre of the scene with an equirectangular projection
(east = dlon * cos(lat0) * R, north = dlat * R). Within 10 km of the centre its scale error is
below 0.2 %, far below one map cell; the map is a picture for the operator, never an input to
a decision (Monitoring and TD compute in the airspace's transverse Mercator frame, gcs_utm.geo).

Separation rings: around the two UAS of each active loss-of-separation threat, a circle of
the pair's horizontal minimum (the larger of ``[monitoring] separation_horizontal_m`` and the
two operational volumes, as Monitoring defines the pair's loss); around a UAS and the intruder
of an INTRUDER threat, the intruder minimum. The other vehicle inside a ring is a loss of
horizontal separation (vertical separation may still hold: the map is seen from above).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs_utm.dashboard.view import DashboardData
from gcs_utm.model import (
    GeofenceShape,
    Operation,
    OperationState,
    ThreatKind,
    ThreatStatus,
    Track,
    TrackId,
)

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius (IUGG) of the map's equirectangular projection."""

HOVER_SPEED_MPS = 0.5
"""Below this ground speed a vehicle has no meaningful course: drawn without a heading."""

Point = tuple[float, float]
"""(east_m, north_m) in the map's local frame."""


@dataclass(frozen=True, slots=True)
class MapVehicle:
    """A tracked vehicle: a UAS of an operation or an intruder (ADS-B / Remote ID traffic)."""

    label: str
    east_m: float
    north_m: float
    course_deg: float | None
    """Course over ground, degrees clockwise from north; None when hovering."""
    intruder: bool = False
    stale: bool = False
    in_threat: bool = False
    """One of the pair of an active separation threat (drawn highlighted: at a scale where
    the separation ring is smaller than a cell the highlight still shows the pair)."""


@dataclass(frozen=True, slots=True)
class MapPlan:
    """An operation's current filed plan, its waypoints in order."""

    label: str
    points: tuple[Point, ...]


@dataclass(frozen=True, slots=True)
class MapFence:
    """A geofence outline: a polygon (``vertices``) or a circle (``center`` and radius)."""

    label: str
    vertices: tuple[Point, ...] = ()
    center: Point | None = None
    radius_m: float = 0.0


@dataclass(frozen=True, slots=True)
class MapRing:
    """A separation ring: the horizontal minimum around one vehicle of a threat's pair."""

    center: Point
    radius_m: float


@dataclass(frozen=True, slots=True)
class MapScene:
    vehicles: tuple[MapVehicle, ...] = ()
    plans: tuple[MapPlan, ...] = ()
    fences: tuple[MapFence, ...] = ()
    rings: tuple[MapRing, ...] = ()

    def points(self) -> list[Point]:
        """Every point the map must show (circles by their bounding boxes' corners)."""
        pts: list[Point] = [(v.east_m, v.north_m) for v in self.vehicles]
        for p in self.plans:
            pts.extend(p.points)
        circles = [(f.center, f.radius_m) for f in self.fences if f.center is not None]
        circles += [(r.center, r.radius_m) for r in self.rings]
        for f in self.fences:
            pts.extend(f.vertices)
        for c, r in circles:
            if c is not None:
                pts += [(c[0] - r, c[1] - r), (c[0] + r, c[1] + r)]
        return pts


def course_deg(track: Track) -> float | None:
    """Course over ground of ``track`` in degrees clockwise from north (None: hovering)."""
    ve, vn = track.vel_enu_mps[0], track.vel_enu_mps[1]
    if math.hypot(ve, vn) < HOVER_SPEED_MPS:
        return None
    return math.degrees(math.atan2(ve, vn)) % 360.0


def _label(track: Track) -> str:
    """A track's map label: its operation id, or the intruder's id without its source prefix
    (``icao:a1b2c3`` -> ``a1b2c3``; the style already says it is an intruder)."""
    if track.cooperative:
        return str(track.operation_id or track.id)
    return str(track.id).split(":", 1)[-1]


class _Projection:
    """WGS84 -> local metres around (lat0, lon0), equirectangular (module docstring)."""

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0_deg = lat0_deg
        self.lon0_deg = lon0_deg
        self.k_east = math.radians(1.0) * EARTH_RADIUS_M * math.cos(math.radians(lat0_deg))
        self.k_north = math.radians(1.0) * EARTH_RADIUS_M

    def __call__(self, lat_deg: float, lon_deg: float) -> Point:
        return ((lon_deg - self.lon0_deg) * self.k_east, (lat_deg - self.lat0_deg) * self.k_north)


def _projection(d: DashboardData) -> _Projection | None:
    lats: list[float] = []
    lons: list[float] = []
    for op in d.operations:
        lats += [w.lat_deg for w in op.plan.waypoints]
        lons += [w.lon_deg for w in op.plan.waypoints]
    lats += [t.lat_deg for t in d.tracks.values()]
    lons += [t.lon_deg for t in d.tracks.values()]
    for g in d.geofences:
        ll = [*g.vertices, *([g.center] if g.center is not None else [])]
        lats += [p.lat_deg for p in ll]
        lons += [p.lon_deg for p in ll]
    if not lats:
        return None
    return _Projection((min(lats) + max(lats)) / 2.0, (min(lons) + max(lons)) / 2.0)


def _pair_minimum_m(
    d: DashboardData, ops: dict[str, Operation], kind: ThreatKind, uas: list[str]
) -> float | None:
    """The horizontal minimum of a threat's pair (module docstring), None when not known."""
    if d.minima is None:
        return None
    h_m, _v_m = d.minima.for_threat(kind)
    if h_m is None:
        return None
    if kind is ThreatKind.LOSS_OF_SEPARATION:
        floor_m = sum(ops[u].operational_volume_m for u in uas if u in ops)
        return max(h_m, floor_m)
    return h_m


def _threat_pairs(d: DashboardData) -> list[tuple[list[Track], float | None]]:
    """The tracks of each active separation threat (two UAS, or a UAS and its intruder)
    with the pair's horizontal minimum (module docstring; None when not known)."""
    ops = {str(op.id): op for op in d.operations}
    by_op = {str(t.operation_id): t for t in d.tracks.values() if t.operation_id is not None}
    pairs: list[tuple[list[Track], float | None]] = []
    for threat in d.threats:
        if threat.status is ThreatStatus.CLOSED:
            continue
        if threat.kind is ThreatKind.LOSS_OF_SEPARATION and len(threat.uas_ids) == 2:
            members = [by_op.get(str(u)) for u in threat.uas_ids]
        elif threat.kind is ThreatKind.INTRUDER and threat.intruder_id is not None:
            members = [by_op.get(str(u)) for u in threat.uas_ids[:1]]
            members.append(d.tracks.get(TrackId(threat.intruder_id)))
        else:
            continue
        radius_m = _pair_minimum_m(d, ops, threat.kind, [str(u) for u in threat.uas_ids])
        pairs.append(([t for t in members if t is not None], radius_m))
    return pairs


def scene_of(d: DashboardData) -> MapScene:
    """The map's view model of snapshot ``d``: tracked vehicles with their course, the
    current plan of every operation not yet landed or ended, the active geofences and the
    separation rings of the active threats (module docstring)."""
    project = _projection(d)
    if project is None:
        return MapScene()
    pairs = _threat_pairs(d)
    in_threat = {t.id for members, _r in pairs for t in members}
    rings: list[MapRing] = []
    for members, radius_m in pairs:
        if radius_m is None:
            continue
        for t in members:
            ring = MapRing(project(t.lat_deg, t.lon_deg), radius_m)
            if ring not in rings:
                rings.append(ring)
    vehicles = tuple(
        MapVehicle(
            label=_label(t),
            east_m=project(t.lat_deg, t.lon_deg)[0],
            north_m=project(t.lat_deg, t.lon_deg)[1],
            course_deg=course_deg(t),
            intruder=not t.cooperative,
            stale=t.stale,
            in_threat=t.id in in_threat,
        )
        for t in sorted(d.tracks.values(), key=lambda t: (not t.cooperative, t.id))
    )
    plans = tuple(
        MapPlan(str(op.id), tuple(project(w.lat_deg, w.lon_deg) for w in op.plan.waypoints))
        for op in d.operations
        if op.state in (OperationState.PLANNED, OperationState.ACTIVE, OperationState.SUSPENDED)
    )
    fences: list[MapFence] = []
    for g in d.geofences:
        if g.shape is GeofenceShape.CYLINDER and g.center is not None and g.radius_m is not None:
            c = project(g.center.lat_deg, g.center.lon_deg)
            fences.append(MapFence(str(g.id), center=c, radius_m=g.radius_m))
        elif g.vertices:
            fences.append(
                MapFence(
                    str(g.id), vertices=tuple(project(v.lat_deg, v.lon_deg) for v in g.vertices)
                )
            )
    return MapScene(vehicles=vehicles, plans=plans, fences=tuple(fences), rings=tuple(rings))
