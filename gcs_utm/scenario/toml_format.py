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
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from shapely.geometry import Polygon

from gcs_utm.config import ConfigError, load_toml
from gcs_utm.geo import FrameError, LocalFrame
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
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
    """Shared state while reading one file: the frame and the ground elevation."""

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
        east = t.req_number("east_m")
        north = t.req_number("north_m")
        lat_a, lon_a, _ = self.frame.enu_to_wgs84(east, north, 0.0)
        return LatLon(lat_deg=float(lat_a), lon_deg=float(lon_a))

    def altitude(self, t: _Table, stem: str = "alt", *, required: bool = True) -> float | None:
        """``<stem>_agl_m`` or ``<stem>_amsl_m`` -> metres AMSL."""
        agl_key, amsl_key = f"{stem}_agl_m", f"{stem}_amsl_m"
        if t.has(agl_key) and t.has(amsl_key):
            raise t.err(agl_key, f"give either {agl_key} or {amsl_key}, not both")
        if t.has(agl_key):
            return float(self.frame.agl_to_amsl(t.req_number(agl_key)))
        if t.has(amsl_key):
            return t.req_number(amsl_key)
        if required:
            raise t.err(agl_key, f"missing; expected {agl_key} or {amsl_key}")
        return None

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

    def volume(self, t: _Table, gid: str, kind: GeofenceKind, reason: str) -> Geofence:
        """A cylinder or polygon with an altitude band and optional validity window."""
        if t.has("cylinder") == t.has("polygon"):
            raise t.err("cylinder", "give exactly one of cylinder or polygon")
        center: LatLon | None = None
        radius_m: float | None = None
        vertices: tuple[LatLon, ...] = ()
        if t.has("cylinder"):
            c = t.sub("cylinder", t.raw("cylinder"))
            center = self.latlon(c)
            radius_m = c.req_number("radius_m", positive=True)
            c.done()
            shape = GeofenceShape.CYLINDER
        else:
            raw = t.array("polygon")
            if len(raw) < 3:
                raise t.err("polygon", f"a polygon needs at least 3 vertices, got {len(raw)}")
            pts = []
            for i, v in enumerate(raw):
                vt = t.sub(f"polygon[{i}]", v)
                pts.append(self.latlon(vt))
                vt.done()
            vertices = tuple(pts)
            east, north = self.frame.to_local(
                np.array([p.lat_deg for p in pts]), np.array([p.lon_deg for p in pts])
            )
            poly = Polygon(list(zip(east.tolist(), north.tolist(), strict=True)))
            if not poly.is_valid or poly.area <= 0.0:
                raise t.err("polygon", "the polygon intersects itself or has no area")
            shape = GeofenceShape.POLYGON
        lo = self.altitude(t, "min_alt")
        hi = self.altitude(t, "max_alt")
        assert lo is not None and hi is not None
        if lo > hi:
            raise t.err("min_alt", f"minimum altitude {lo} m AMSL is above maximum {hi} m AMSL")
        start = t.number("start_s")
        end = t.number("end_s")
        if start is not None and end is not None and start > end:
            raise t.err("start_s", f"start_s {start} is after end_s {end}")
        return Geofence(
            id=GeofenceId(gid),
            shape=shape,
            min_alt_amsl_m=lo,
            max_alt_amsl_m=hi,
            center=center,
            radius_m=radius_m,
            vertices=vertices,
            start_t_s=None if start is None else self.t0_s + start,
            end_t_s=None if end is None else self.t0_s + end,
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
    for name in _SECTIONS:
        top.used.add(name)
    top.done()

    if "scenario" not in doc:
        raise ScenarioError(file, "scenario", "(table)", "missing [scenario] table")
    sc = _Table(file, "scenario", doc["scenario"])
    name = sc.req_string("name")
    description = sc.string("description") or ""
    duration_s = sc.req_number("duration_s", positive=True)
    sc.done()

    if "airspace" not in doc:
        raise ScenarioError(file, "airspace", "(table)", "missing [airspace] table")
    air = _Table(file, "airspace", doc["airspace"])
    lat0 = air.req_number("origin_lat_deg")
    lon0 = air.req_number("origin_lon_deg")
    if not -90.0 <= lat0 <= 90.0:
        raise air.err("origin_lat_deg", f"must be in [-90, 90], got {lat0}")
    if not -180.0 <= lon0 <= 180.0:
        raise air.err("origin_lon_deg", f"must be in [-180, 180], got {lon0}")
    ground = air.req_number("ground_elevation_amsl_m")
    air.done()
    try:
        frame = LocalFrame(lat0, lon0, ground)
    except FrameError as exc:
        raise ScenarioError(file, "airspace", "origin_lat_deg", str(exc)) from exc
    rd = _Reader(file, frame, t0_s)

    # Shared landing sites, referenced by id from operations.
    sites: dict[str, Position] = {}
    for i, raw in enumerate(_list_of_tables(file, doc, "landing_sites")):
        t = _Table(file, f"landing_sites[{i}]", raw)
        sid = t.req_string("id")
        t.item = f"landing_sites[{i}] ({sid})"
        if sid in sites:
            raise t.err("id", f"duplicate landing site id {sid!r}")
        sites[sid] = rd.position(t)
        t.done()

    operations: list[Operation] = []
    vehicles: list[VehicleSetup] = []
    seen_sys: dict[int, str] = {}
    seen_icao: dict[str, str] = {}
    for i, raw in enumerate(_list_of_tables(file, doc, "operations")):
        t = _Table(file, f"operations[{i}]", raw)
        op_id = t.req_string("id")
        t.item = f"operations[{i}] ({op_id})"
        if any(o.id == op_id for o in operations):
            raise t.err("id", f"duplicate operation id {op_id!r}")
        icao_text = t.string("icao24")
        icao = None
        if icao_text is not None:
            try:
                icao = normalise_icao24(icao_text)
            except ModelError as exc:
                raise t.err("icao24", exc.message) from None
            if icao in seen_icao:
                raise t.err("icao24", f"{icao} is also used by {seen_icao[icao]}")
            seen_icao[icao] = op_id
        sys_id = t.integer("sys_id")
        if sys_id is not None:
            if not 1 <= sys_id <= 255:
                raise t.err("sys_id", f"must be in 1..255, got {sys_id}")
            if sys_id in seen_sys:
                raise t.err("sys_id", f"{sys_id} is also used by {seen_sys[sys_id]}")
            seen_sys[sys_id] = op_id
        priority = t.integer("priority", required=True)
        assert priority is not None
        conops = t.string("conops") or ""
        vehicle = t.choice("vehicle", _VEHICLES, VehicleKind.MULTIROTOR)
        autopilot = t.choice("autopilot", _AUTOPILOTS, Autopilot.PX4)
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
        operator = t.string("operator") or "default"
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
            if j == 0:
                if t_rel is not None and start_s is not None:
                    raise w.err("t_s", "give either the operation's start_s or waypoints[0].t_s")
                if speed is not None:
                    raise w.err("speed_mps", "the first waypoint has no segment to fly")
                t_rel = t_rel if t_rel is not None else (start_s or 0.0)
            else:
                assert prev is not None
                if t_rel is None:
                    t_rel = prev_t + _segment_m(frame, prev, pos) / (speed or cruise)
                elif t_rel < prev_t:
                    raise w.err("t_s", f"time goes backwards ({t_rel} < {prev_t})")
            if t_rel < 0.0:
                raise w.err("t_s", f"must be >= 0 (seconds after scenario start), got {t_rel}")
            waypoints.append(
                Waypoint4D(
                    lat_deg=pos.lat_deg,
                    lon_deg=pos.lon_deg,
                    alt_amsl_m=pos.alt_amsl_m,
                    t_s=t0_s + t_rel,
                )
            )
            prev, prev_t = pos, t_rel
        plan = FlightPlan(
            operation_id=OperationId(op_id),
            version=1,
            waypoints=tuple(waypoints),
            created_t_s=t0_s,
            reason="filed",
        )
        if endurance is not None and plan.end_t_s - plan.start_t_s > endurance:
            raise t.err(
                "endurance_s",
                f"the plan lasts {plan.end_t_s - plan.start_t_s:.0f} s, longer than {endurance} s",
            )
        if t.has("home"):
            home = rd.point_table(t, "home", t.raw("home"))
        else:
            # No home given: take off from the ground under the first waypoint.
            home = Position(
                lat_deg=waypoints[0].lat_deg,
                lon_deg=waypoints[0].lon_deg,
                alt_amsl_m=frame.ground_elevation_amsl_m,
            )
        op_sites: list[Position] = []
        for k, s in enumerate(t.array("landing_sites")):
            if isinstance(s, str):
                if s not in sites:
                    raise t.err(
                        f"landing_sites[{k}]",
                        f"unknown landing site {s!r}; known: {', '.join(sorted(sites)) or 'none'}",
                    )
                op_sites.append(sites[s])
            else:
                op_sites.append(rd.point_table(t, f"landing_sites[{k}]", s))
        t.done()
        operation = Operation(
            id=OperationId(op_id),
            icao24=icao,
            sys_id=None if sys_id is None else SysId(sys_id),
            priority=priority,
            plan=plan,
            vehicle_kind=vehicle,
            cruise_speed_mps=cruise,
            flight_geometry_m=geometry,
            operational_volume_m=volume,
            conops=conops,
            home=home,
            landing_sites=tuple(op_sites),
            autopilot=autopilot,
            max_climb_rate_mps=climb,
            endurance_s=endurance,
            operator=operator,
        )
        operations.append(operation)
        vehicles.append(
            VehicleSetup(
                operation_id=operation.id,
                sys_id=operation.sys_id,
                icao24=icao,
                autopilot=autopilot,
                vehicle_kind=vehicle,
                home=home,
                plan=plan,
                cruise_speed_mps=cruise,
                max_climb_rate_mps=climb,
                start_delay_s=delay,
                endurance_s=endurance,
            )
        )

    geofences: list[Geofence] = []
    for i, raw in enumerate(_list_of_tables(file, doc, "geofences")):
        t = _Table(file, f"geofences[{i}]", raw)
        gid = t.req_string("id")
        t.item = f"geofences[{i}] ({gid})"
        if any(g.id == gid for g in geofences):
            raise t.err("id", f"duplicate geofence id {gid!r}")
        kind = t.choice("kind", _GEOFENCE_KINDS, GeofenceKind.STATIC)
        reason = t.string("reason") or ""
        geofences.append(rd.volume(t, gid, kind, reason))
        t.done()

    op_ids = {o.id for o in operations}
    events: list[ScenarioEvent] = []
    for i, raw in enumerate(_list_of_tables(file, doc, "events")):
        t = _Table(file, f"events[{i}]", raw)
        kind_text = t.req_string("kind")
        t.item = f"events[{i}] ({kind_text})"
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
        value = t.number("value")
        reason = t.string("reason") or ""
        area: Geofence | None = None
        if t.has("area"):
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
        if ev_kind is EventKind.ALERT_AREA and area is None:
            raise t.err("area", "an alert_area event needs an area (cylinder or polygon)")
        if ev_kind is not EventKind.ALERT_AREA and area is not None:
            raise t.err("area", f"only alert_area events take an area, not {kind_text}")
        t.done()
        events.append(
            ScenarioEvent(
                at_s=at_s,
                t_s=t0_s + at_s,
                kind=ev_kind,
                uas=None if uas is None else OperationId(uas),
                duration_s=dur,
                value=value,
                area=area,
                reason=reason,
            )
        )
    events.sort(key=lambda e: e.at_s)
    return Scenario(
        name=name,
        description=description,
        duration_s=duration_s,
        t0_s=t0_s,
        frame=frame,
        operations=tuple(operations),
        geofences=tuple(geofences),
        events=tuple(events),
        vehicles=tuple(vehicles),
        source=file,
    )


def _list_of_tables(file: str, doc: dict[str, Any], name: str) -> list[Any]:
    value = doc.get(name, [])
    if not isinstance(value, list):
        raise ScenarioError(file, name, "(table)", f"expected [[{name}]] (an array of tables)")
    return value
