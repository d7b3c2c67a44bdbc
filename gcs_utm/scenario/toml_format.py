"""Loader of our TOML scenario format (documented in docs/formats.md).

Positions are given either as WGS84 (``lat_deg``/``lon_deg``) or as local ENU metres from the
airspace origin (``east_m``/``north_m``); altitudes either ``alt_agl_m`` (converted with the
airspace's ground elevation, explicitly) or ``alt_amsl_m``. Waypoint times are either given
(``t_s``, seconds after scenario start) or computed from the 3D segment length and the speed
(``speed_mps`` of the waypoint, else the operation's ``cruise_speed_mps``), starting at the
operation's ``start_s``.

Every problem is a :class:`ScenarioError` naming the file, the item and the field; all
checking happens before the :class:`Scenario` is built, so nothing is ever half-loaded.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from gcs_utm.config import ConfigError, load_toml
from gcs_utm.flyable import plan_problem
from gcs_utm.geo import FrameError, LocalFrame
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
    Icao24,
    LatLon,
    ModelError,
    Operation,
    OperationId,
    Position,
    SysId,
    VehicleKind,
    Waypoint4D,
    normalise_icao24,
)
from gcs_utm.scenario.types import (
    EventKind,
    Scenario,
    ScenarioError,
    ScenarioEvent,
    VehicleSetup,
)
from gcs_utm.validation import altitude_problem, offset_problem, polygon_problem, radius_problem

T = TypeVar("T")

_SECTIONS = ("scenario", "airspace", "operations", "geofences", "landing_sites", "events")


class _Table:
    """One TOML table being read: typed getters that name the item and field on error, and a
    final :meth:`done` that rejects keys nobody asked for (typos are errors, not ignored)."""

    def __init__(self, file: str, item: str, data: Any, prefix: str = "") -> None:
        self.file = file
        self.item = item
        self.prefix = prefix
        if not isinstance(data, dict):
            raise ScenarioError(file, item, prefix.rstrip(".") or "(table)", "expected a table")
        self.data: dict[str, Any] = data
        self.used: set[str] = set()

    def err(self, name: str, message: str) -> ScenarioError:
        return ScenarioError(self.file, self.item, self.prefix + name, message)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str) -> Any:
        self.used.add(name)
        return self.data.get(name)

    def _get(self, name: str, check: Callable[[Any], T], what: str, required: bool) -> T | None:
        self.used.add(name)
        if name not in self.data:
            if required:
                raise self.err(name, f"missing; expected {what}")
            return None
        value = self.data[name]
        try:
            return check(value)
        except (TypeError, ValueError) as exc:
            detail = str(exc) or f"expected {what}, got {value!r}"
            raise self.err(name, detail) from None

    def number(self, name: str, *, required: bool = False, positive: bool = False) -> float | None:
        def check(v: Any) -> float:
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise TypeError(f"expected a number, got {v!r}")
            f = float(v)
            if not math.isfinite(f):
                raise ValueError(f"expected a finite number, got {v!r}")
            if positive and f <= 0.0:
                raise ValueError(f"expected a positive number, got {v!r}")
            return f

        return self._get(name, check, "a number", required)

    def req_number(self, name: str, *, positive: bool = False) -> float:
        value = self.number(name, required=True, positive=positive)
        assert value is not None
        return value

    def string(self, name: str, *, required: bool = False) -> str | None:
        def check(v: Any) -> str:
            if not isinstance(v, str):
                raise TypeError(f"expected a string, got {v!r}")
            return v

        return self._get(name, check, "a string", required)

    def req_string(self, name: str) -> str:
        value = self.string(name, required=True)
        assert value is not None
        if not value.strip():
            raise self.err(name, "must not be empty")
        return value

    def integer(self, name: str, *, required: bool = False) -> int | None:
        def check(v: Any) -> int:
            if isinstance(v, bool) or not isinstance(v, int):
                raise TypeError(f"expected an integer, got {v!r}")
            return v

        return self._get(name, check, "an integer", required)

    def choice(self, name: str, options: Mapping[str, T], default: T) -> T:
        text = self.string(name)
        if text is None:
            return default
        if text not in options:
            raise self.err(name, f"expected one of {', '.join(map(repr, options))}, got {text!r}")
        return options[text]

    def array(self, name: str) -> list[Any]:
        value = self.raw(name)
        if value is None:
            return []
        if not isinstance(value, list):
            raise self.err(name, f"expected an array, got {value!r}")
        return value

    def sub(self, name: str, data: Any) -> _Table:
        return _Table(self.file, self.item, data, f"{self.prefix}{name}.")

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.err(
                unknown[0], "unknown key; valid keys here are: " + ", ".join(sorted(self.used))
            )


class _Reader:
    """Shared state while reading one file: the frame and the ground elevation. Positions
    and altitudes are checked against the plausibility bounds of :mod:`gcs_utm.validation`
    (the same for every input)."""

    def __init__(self, file: str, frame: LocalFrame, t0_s: float) -> None:
        self.file = file
        self.frame = frame
        self.t0_s = t0_s

    def latlon(self, t: _Table) -> LatLon:
        """A horizontal position: ``lat_deg``/``lon_deg`` or ``east_m``/``north_m``."""
        geo = t.has("lat_deg") or t.has("lon_deg")
        local = t.has("east_m") or t.has("north_m")
        if geo and local:
            raise t.err("lat_deg", "give either lat_deg/lon_deg or east_m/north_m, not both")
        if not geo and not local:
            raise t.err("lat_deg", "missing; expected lat_deg/lon_deg or east_m/north_m")
        if geo:
            lat = t.req_number("lat_deg")
            lon = t.req_number("lon_deg")
            if not -90.0 <= lat <= 90.0:
                raise t.err("lat_deg", f"must be in [-90, 90], got {lat}")
            if not -180.0 <= lon <= 180.0:
                raise t.err("lon_deg", f"must be in [-180, 180], got {lon}")
            return LatLon(lat_deg=lat, lon_deg=lon)
        east = self._offset(t, "east_m")
        north = self._offset(t, "north_m")
        lat_a, lon_a, _ = self.frame.enu_to_wgs84(east, north, 0.0)
        return LatLon(lat_deg=float(lat_a), lon_deg=float(lon_a))

    @staticmethod
    def _offset(t: _Table, name: str) -> float:
        value = t.req_number(name)
        problem = offset_problem(value)
        if problem is not None:
            raise t.err(name, problem)
        return value

    def altitude(self, t: _Table, stem: str = "alt", *, required: bool = True) -> float | None:
        """``<stem>_agl_m`` or ``<stem>_amsl_m`` -> metres AMSL."""
        agl_key, amsl_key = f"{stem}_agl_m", f"{stem}_amsl_m"
        if t.has(agl_key) and t.has(amsl_key):
            raise t.err(agl_key, f"give either {agl_key} or {amsl_key}, not both")
        if t.has(agl_key):
            ground = self.frame.ground_elevation_amsl_m
            alt = float(self.frame.agl_to_amsl(t.req_number(agl_key)))
            problem = altitude_problem(alt, ground_amsl_m=ground)
            key = agl_key
        elif t.has(amsl_key):
            alt = t.req_number(amsl_key)
            problem = altitude_problem(alt)
            key = amsl_key
        elif required:
            raise t.err(agl_key, f"missing; expected {agl_key} or {amsl_key}")
        else:
            return None
        if problem is not None:
            raise t.err(key, problem)
        return alt

    def position(self, t: _Table) -> Position:
        ll = self.latlon(t)
        alt = self.altitude(t)
        assert alt is not None
        return Position(lat_deg=ll.lat_deg, lon_deg=ll.lon_deg, alt_amsl_m=alt)

    def point_table(self, parent: _Table, name: str, data: Any) -> Position:
        t = parent.sub(name, data)
        pos = self.position(t)
        t.done()
        return pos

    def _cylinder(self, t: _Table) -> tuple[LatLon, float]:
        c = t.sub("cylinder", t.raw("cylinder"))
        center = self.latlon(c)
        radius_m = c.req_number("radius_m", positive=True)
        problem = radius_problem(radius_m)
        if problem is not None:
            raise c.err("radius_m", problem)
        c.done()
        return center, radius_m

    def _polygon(self, t: _Table) -> tuple[LatLon, ...]:
        raw = t.array("polygon")
        pts = []
        for i, v in enumerate(raw):
            vt = t.sub(f"polygon[{i}]", v)
            pts.append(self.latlon(vt))
            vt.done()
        problem = polygon_problem([(p.lat_deg, p.lon_deg) for p in pts])
        if problem is not None:
            raise t.err("polygon", problem)
        return tuple(pts)

    def _window(self, t: _Table) -> tuple[float | None, float | None]:
        start = t.number("start_s")
        end = t.number("end_s")
        if start is not None and end is not None and start > end:
            raise t.err("start_s", f"start_s {start} is after end_s {end}")
        return (
            None if start is None else self.t0_s + start,
            None if end is None else self.t0_s + end,
        )

    def volume(self, t: _Table, gid: str, kind: GeofenceKind, reason: str) -> Geofence:
        """A cylinder or polygon with an altitude band and optional validity window."""
        if t.has("cylinder") == t.has("polygon"):
            raise t.err("cylinder", "give exactly one of cylinder or polygon")
        center: LatLon | None = None
        radius_m: float | None = None
        vertices: tuple[LatLon, ...] = ()
        if t.has("cylinder"):
            center, radius_m = self._cylinder(t)
            shape = GeofenceShape.CYLINDER
        else:
            vertices = self._polygon(t)
            shape = GeofenceShape.POLYGON
        lo = self.altitude(t, "min_alt")
        hi = self.altitude(t, "max_alt")
        assert lo is not None and hi is not None
        if lo > hi:
            raise t.err("min_alt", f"minimum altitude {lo} m AMSL is above maximum {hi} m AMSL")
        start_t_s, end_t_s = self._window(t)
        return Geofence(
            id=GeofenceId(gid),
            shape=shape,
            min_alt_amsl_m=lo,
            max_alt_amsl_m=hi,
            center=center,
            radius_m=radius_m,
            vertices=vertices,
            start_t_s=start_t_s,
            end_t_s=end_t_s,
            kind=kind,
            reason=reason,
            source=self.file,
        )


def _segment_m(frame: LocalFrame, a: Position, b: Position) -> float:
    """True 3D length in metres: local ENU, not UTM grid metres (which carry the projection's
    scale error of up to ~0.1 %, enough to shift a long plan's times by seconds)."""
    e, n, u = frame.wgs84_to_enu(
        np.array([a.lat_deg, b.lat_deg]),
        np.array([a.lon_deg, b.lon_deg]),
        np.array([a.alt_amsl_m, b.alt_amsl_m]),
    )
    return float(math.sqrt((e[1] - e[0]) ** 2 + (n[1] - n[0]) ** 2 + (u[1] - u[0]) ** 2))


_VEHICLES = {k.value: k for k in VehicleKind}
_AUTOPILOTS = {"px4": Autopilot.PX4, "ardupilot": Autopilot.ARDUPILOT}
_GEOFENCE_KINDS = {k.value: k for k in GeofenceKind}
_EVENT_KINDS = {k.value: k for k in EventKind}


def load_scenario(path: str | Path, *, t0_s: float = 0.0) -> Scenario:
    """Load and validate a TOML scenario; plan, geofence and event times become
    ``t0_s`` + the file's relative seconds."""
    file = str(path)
    if not math.isfinite(t0_s):
        raise ScenarioError(file, "(call)", "t0_s", f"must be finite, got {t0_s}")
    try:
        doc = load_toml(path)
    except ConfigError as exc:
        raise ScenarioError(file, "(file)", exc.key, exc.expected) from exc
    try:
        return _load(file, doc, t0_s)
    except ModelError as exc:
        # The model's own checks caught something the loader did not: still name the file.
        raise ScenarioError(file, exc.item, exc.field_name, exc.message) from exc
    except FrameError as exc:
        raise ScenarioError(file, "airspace", "origin", str(exc)) from exc


def _load(file: str, doc: dict[str, Any], t0_s: float) -> Scenario:
    top = _Table(file, "(top level)", doc)
    top.used.update(_SECTIONS)
    top.done()
    name, description, duration_s = _header(file, doc)
    rd = _Reader(file, _airspace(file, doc), t0_s)
    sites = _landing_sites(rd, doc)
    operations, vehicles = _operations(rd, doc, sites)
    geofences = _geofences(rd, doc)
    events = _events(rd, doc, duration_s, {o.id for o in operations})
    return Scenario(
        name=name,
        description=description,
        duration_s=duration_s,
        t0_s=t0_s,
        frame=rd.frame,
        operations=tuple(operations),
        geofences=tuple(geofences),
        events=tuple(events),
        vehicles=tuple(vehicles),
        source=file,
    )


def _required_table(file: str, doc: dict[str, Any], name: str) -> _Table:
    if name not in doc:
        raise ScenarioError(file, name, "(table)", f"missing [{name}] table")
    return _Table(file, name, doc[name])


def _header(file: str, doc: dict[str, Any]) -> tuple[str, str, float]:
    sc = _required_table(file, doc, "scenario")
    name = sc.req_string("name")
    description = sc.string("description") or ""
    duration_s = sc.req_number("duration_s", positive=True)
    sc.done()
    return name, description, duration_s


def _airspace(file: str, doc: dict[str, Any]) -> LocalFrame:
    air = _required_table(file, doc, "airspace")
    lat0 = air.req_number("origin_lat_deg")
    lon0 = air.req_number("origin_lon_deg")
    if not -90.0 <= lat0 <= 90.0:
        raise air.err("origin_lat_deg", f"must be in [-90, 90], got {lat0}")
    if not -180.0 <= lon0 <= 180.0:
        raise air.err("origin_lon_deg", f"must be in [-180, 180], got {lon0}")
    ground = air.req_number("ground_elevation_amsl_m")
    problem = altitude_problem(ground)
    if problem is not None:
        raise air.err("ground_elevation_amsl_m", problem)
    air.done()
    try:
        return LocalFrame(lat0, lon0, ground)
    except FrameError as exc:
        raise ScenarioError(file, "airspace", "origin_lat_deg", str(exc)) from exc


def _items(rd: _Reader, doc: dict[str, Any], section: str, key: str) -> Iterator[_Table]:
    """The tables of ``[[section]]``, each named by its index and then by its ``key``."""
    for i, raw in enumerate(_list_of_tables(rd.file, doc, section)):
        t = _Table(rd.file, f"{section}[{i}]", raw)
        t.item = f"{section}[{i}] ({t.req_string(key)})"
        yield t


def _landing_sites(rd: _Reader, doc: dict[str, Any]) -> dict[str, Position]:
    """Shared landing sites, referenced by id from operations."""
    sites: dict[str, Position] = {}
    for t in _items(rd, doc, "landing_sites", "id"):
        sid = t.req_string("id")
        if sid in sites:
            raise t.err("id", f"duplicate landing site id {sid!r}")
        sites[sid] = rd.position(t)
        t.done()
    return sites


class _Identities:
    """The ids, ICAO addresses and system ids seen so far: each may be used once."""

    def __init__(self) -> None:
        self.ops: set[str] = set()
        self.icao: dict[str, str] = {}
        self.sys: dict[int, str] = {}

    def operation(self, t: _Table) -> str:
        op_id = t.req_string("id")
        if op_id in self.ops:
            raise t.err("id", f"duplicate operation id {op_id!r}")
        self.ops.add(op_id)
        return op_id

    def icao24(self, t: _Table, op_id: str) -> Icao24 | None:
        text = t.string("icao24")
        if text is None:
            return None
        try:
            icao = normalise_icao24(text)
        except ModelError as exc:
            raise t.err("icao24", exc.message) from None
        if icao in self.icao:
            raise t.err("icao24", f"{icao} is also used by {self.icao[icao]}")
        self.icao[icao] = op_id
        return icao

    def sys_id(self, t: _Table, op_id: str) -> SysId | None:
        sys_id = t.integer("sys_id")
        if sys_id is None:
            return None
        if not 1 <= sys_id <= 255:
            raise t.err("sys_id", f"must be in 1..255, got {sys_id}")
        if sys_id in self.sys:
            raise t.err("sys_id", f"{sys_id} is also used by {self.sys[sys_id]}")
        self.sys[sys_id] = op_id
        return SysId(sys_id)


@dataclass(frozen=True, slots=True)
class _Performance:
    cruise_mps: float
    geometry_m: float
    volume_m: float
    climb_mps: float
    endurance_s: float | None
    delay_s: float


def _performance(t: _Table) -> _Performance:
    cruise = t.req_number("cruise_speed_mps", positive=True)
    geometry = t.req_number("flight_geometry_m", positive=True)
    volume = t.req_number("operational_volume_m", positive=True)
    if volume < geometry:
        raise t.err("operational_volume_m", f"{volume} is below flight_geometry_m {geometry}")
    climb = t.number("max_climb_rate_mps", positive=True) or 3.0
    endurance = t.number("endurance_s", positive=True)
    delay = t.number("start_delay_s") or 0.0
    if delay < 0.0:
        raise t.err("start_delay_s", f"must be >= 0, got {delay}")
    return _Performance(cruise, geometry, volume, climb, endurance, delay)


def _operations(
    rd: _Reader, doc: dict[str, Any], sites: dict[str, Position]
) -> tuple[list[Operation], list[VehicleSetup]]:
    operations: list[Operation] = []
    vehicles: list[VehicleSetup] = []
    ids = _Identities()
    for t in _items(rd, doc, "operations", "id"):
        op, vehicle = _operation(rd, t, sites, ids)
        operations.append(op)
        vehicles.append(vehicle)
    return operations, vehicles


def _operation(
    rd: _Reader, t: _Table, sites: dict[str, Position], ids: _Identities
) -> tuple[Operation, VehicleSetup]:
    op_id = ids.operation(t)
    icao = ids.icao24(t, op_id)
    sys_id = ids.sys_id(t, op_id)
    priority = t.integer("priority", required=True)
    assert priority is not None
    conops = t.string("conops") or ""
    vehicle = t.choice("vehicle", _VEHICLES, VehicleKind.MULTIROTOR)
    autopilot = t.choice("autopilot", _AUTOPILOTS, Autopilot.PX4)
    perf = _performance(t)
    operator = t.string("operator") or "default"
    plan = FlightPlan(
        operation_id=OperationId(op_id),
        version=1,
        waypoints=_waypoints(rd, t, perf.cruise_mps),
        created_t_s=rd.t0_s,
        reason="filed",
    )
    if perf.endurance_s is not None and plan.end_t_s - plan.start_t_s > perf.endurance_s:
        raise t.err(
            "endurance_s",
            f"the plan lasts {plan.end_t_s - plan.start_t_s:.0f} s, longer than "
            f"{perf.endurance_s} s",
        )
    home = _home(rd, t, plan)
    op_sites = _operation_sites(rd, t, sites)
    t.done()
    operation = Operation(
        id=OperationId(op_id),
        icao24=icao,
        sys_id=sys_id,
        priority=priority,
        plan=plan,
        vehicle_kind=vehicle,
        cruise_speed_mps=perf.cruise_mps,
        flight_geometry_m=perf.geometry_m,
        operational_volume_m=perf.volume_m,
        conops=conops,
        home=home,
        landing_sites=op_sites,
        autopilot=autopilot,
        max_climb_rate_mps=perf.climb_mps,
        endurance_s=perf.endurance_s,
        operator=operator,
    )
    problem = plan_problem(operation)
    if problem is not None:  # below a fixed wing's minimum airspeed, or too steep
        raise t.err("waypoints", problem)
    setup = VehicleSetup(
        operation_id=operation.id,
        sys_id=sys_id,
        icao24=icao,
        autopilot=autopilot,
        vehicle_kind=vehicle,
        home=home,
        plan=plan,
        cruise_speed_mps=perf.cruise_mps,
        max_climb_rate_mps=perf.climb_mps,
        start_delay_s=perf.delay_s,
        endurance_s=perf.endurance_s,
    )
    return operation, setup


def _waypoints(rd: _Reader, t: _Table, cruise_mps: float) -> tuple[Waypoint4D, ...]:
    """The filed 4D plan: given times, or times from segment lengths and speeds."""
    start_s = t.number("start_s")
    wps_raw = t.array("waypoints")
    if not wps_raw:
        raise t.err("waypoints", "an operation needs at least one waypoint")
    waypoints: list[Waypoint4D] = []
    prev: Position | None = None
    prev_t = 0.0
    for j, wraw in enumerate(wps_raw):
        w = t.sub(f"waypoints[{j}]", wraw)
        pos = rd.position(w)
        t_rel = w.number("t_s")
        speed = w.number("speed_mps", positive=True)
        w.done()
        if prev is None:
            t_rel = _first_time(w, t_rel, start_s, speed)
        elif t_rel is None:
            t_rel = prev_t + _segment_m(rd.frame, prev, pos) / (speed or cruise_mps)
        elif t_rel < prev_t:
            raise w.err("t_s", f"time goes backwards ({t_rel} < {prev_t})")
        if t_rel < 0.0:
            raise w.err("t_s", f"must be >= 0 (seconds after scenario start), got {t_rel}")
        waypoints.append(
            Waypoint4D(
                lat_deg=pos.lat_deg,
                lon_deg=pos.lon_deg,
                alt_amsl_m=pos.alt_amsl_m,
                t_s=rd.t0_s + t_rel,
            )
        )
        prev, prev_t = pos, t_rel
    return tuple(waypoints)


def _first_time(
    w: _Table, t_rel: float | None, start_s: float | None, speed: float | None
) -> float:
    if t_rel is not None and start_s is not None:
        raise w.err("t_s", "give either the operation's start_s or waypoints[0].t_s")
    if speed is not None:
        raise w.err("speed_mps", "the first waypoint has no segment to fly")
    return t_rel if t_rel is not None else (start_s or 0.0)


def _home(rd: _Reader, t: _Table, plan: FlightPlan) -> Position:
    if t.has("home"):
        return rd.point_table(t, "home", t.raw("home"))
    # No home given: take off from the ground under the first waypoint.
    first = plan.waypoints[0]
    return Position(
        lat_deg=first.lat_deg,
        lon_deg=first.lon_deg,
        alt_amsl_m=rd.frame.ground_elevation_amsl_m,
    )


def _operation_sites(rd: _Reader, t: _Table, sites: dict[str, Position]) -> tuple[Position, ...]:
    out: list[Position] = []
    for k, s in enumerate(t.array("landing_sites")):
        if not isinstance(s, str):
            out.append(rd.point_table(t, f"landing_sites[{k}]", s))
        elif s in sites:
            out.append(sites[s])
        else:
            raise t.err(
                f"landing_sites[{k}]",
                f"unknown landing site {s!r}; known: {', '.join(sorted(sites)) or 'none'}",
            )
    return tuple(out)


def _geofences(rd: _Reader, doc: dict[str, Any]) -> list[Geofence]:
    geofences: list[Geofence] = []
    for t in _items(rd, doc, "geofences", "id"):
        gid = t.req_string("id")
        if any(g.id == gid for g in geofences):
            raise t.err("id", f"duplicate geofence id {gid!r}")
        kind = t.choice("kind", _GEOFENCE_KINDS, GeofenceKind.STATIC)
        reason = t.string("reason") or ""
        geofences.append(rd.volume(t, gid, kind, reason))
        t.done()
    return geofences


def _events(
    rd: _Reader, doc: dict[str, Any], duration_s: float, op_ids: set[OperationId]
) -> list[ScenarioEvent]:
    events = [
        _event(rd, i, t, duration_s, op_ids)
        for i, t in enumerate(_items(rd, doc, "events", "kind"))
    ]
    events.sort(key=lambda e: e.at_s)
    return events


def _event(
    rd: _Reader, i: int, t: _Table, duration_s: float, op_ids: set[OperationId]
) -> ScenarioEvent:
    kind_text = t.req_string("kind")
    if kind_text not in _EVENT_KINDS:
        raise t.err("kind", f"expected one of {', '.join(map(repr, _EVENT_KINDS))}")
    ev_kind = _EVENT_KINDS[kind_text]
    at_s = t.req_number("at_s")
    if not 0.0 <= at_s <= duration_s:
        raise t.err("at_s", f"must be within the scenario [0, {duration_s}] s, got {at_s}")
    uas = t.string("uas")
    if uas is not None and uas not in op_ids:
        raise t.err("uas", f"unknown uas {uas!r}; operations are {', '.join(sorted(op_ids))}")
    if uas is None and ev_kind is not EventKind.ALERT_AREA:
        raise t.err("uas", f"a {kind_text} event needs the uas it hits")
    dur = t.number("duration_s", positive=True)
    reason = t.string("reason") or ""
    area = _event_area(rd, i, t, at_s=at_s, dur=dur, reason=reason) if t.has("area") else None
    if (ev_kind is EventKind.ALERT_AREA) != (area is not None):
        if area is None:
            raise t.err("area", "an alert_area event needs an area (cylinder or polygon)")
        raise t.err("area", f"only alert_area events take an area, not {kind_text}")
    event = ScenarioEvent(
        at_s=at_s,
        t_s=rd.t0_s + at_s,
        kind=ev_kind,
        uas=None if uas is None else OperationId(uas),
        duration_s=dur,
        value=t.number("value"),
        area=area,
        reason=reason,
    )
    t.done()
    return event


def _event_area(
    rd: _Reader, i: int, t: _Table, *, at_s: float, dur: float | None, reason: str
) -> Geofence:
    a = t.sub("area", t.raw("area"))
    a_id = a.string("id") or f"alert-{i}"
    a_reason = a.string("reason") or reason
    if not a.has("start_s"):
        # An alert's area is valid from the alert on unless it says otherwise.
        a.data = {**a.data, "start_s": at_s}
        if dur is not None and not a.has("end_s"):
            a.data["end_s"] = at_s + dur
    area = rd.volume(a, a_id, GeofenceKind.DYNAMIC, a_reason)
    a.done()
    return area


def _list_of_tables(file: str, doc: dict[str, Any], name: str) -> list[Any]:
    value = doc.get(name, [])
    if not isinstance(value, list):
        raise ScenarioError(file, name, "(table)", f"expected [[{name}]] (an array of tables)")
    return value
