"""Loader of the paper's own scenario files (grvcTeam/gauss): an operations or geofences JSON
plus the per-scenario YAML with the origin and the simulation parameters.

GAUSS conventions (from its ``db_manager`` and ``usp_testers`` configs):
- positions ``x, y, z`` are local East-North-Up metres from the YAML origin, ``z`` up from
  ``origin_ellipsoidal_height`` (we treat that height as AMSL, like the paper's simulator);
- ``stamp`` is seconds after scenario start; geofence altitudes are metres above the origin;
- ``icao_address`` is a decimal integer (e.g. 3434000): we keep it as the operation id, as
  the YAML refers to vehicles by it, and derive the 24-bit ICAO hex from it;
- ``simulation.auto_start[].delay`` is *when* the vehicle is started, in seconds after
  scenario start (``gauss_light_sim`` fires its start timer at ``init_time + delay``), not a
  lateness. Once started, GAUSS's simulator places the vehicle where its plan says for the
  current time (``updatePhysics4D`` interpolates the plan at the absolute time; the files
  give no ``cruising_speed``, which would select its speed-based mode): a vehicle started
  after its first stamp skips the start of its plan, it is never late. We reproduce that:
  the simulated vehicle's mission (:attr:`VehicleSetup.plan`) begins at the plan's position
  at the start time, and ``start_delay_s`` is 0. The filed operation keeps its whole plan;
- ``safetyDistance`` is GAUSS's one 3D separation minimum (its Monitoring compares the 3D
  distance of the two trajectories with it): it becomes :attr:`Scenario.safety_distance_m`,
  which runs and strategic checks apply in ``sphere`` separation mode;
- ``simulation.change_param[]`` with ``name: jamming`` is a GNSS jamming event.

GAUSS does not say the vehicle type: a plan whose fastest segment exceeds
:data:`FIXED_WING_MIN_SPEED_MPS` is taken as fixed-wing (the paper's Atlantic I flies 30 m/s,
its M600 multirotors at most ~18 m/s).
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

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
)
from gcs_utm.scenario.types import EventKind, Scenario, ScenarioError, ScenarioEvent, VehicleSetup
from gcs_utm.validation import (
    altitude_problem,
    nesting_problem,
    offset_problem,
    polygon_problem,
    radius_problem,
    too_deep,
)

_log = logging.getLogger(__name__)

FIXED_WING_MIN_SPEED_MPS = 20.0
"""Above the top speed of the paper's multirotors: a faster plan is flown by a fixed wing."""


def _read_json(path: Path, file: str) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ScenarioError(file, "(file)", "(file)", "the file does not exist") from exc
    except IsADirectoryError as exc:
        raise ScenarioError(file, "(file)", "(file)", "is a directory, not a file") from exc
    except json.JSONDecodeError as exc:
        raise ScenarioError(
            file, "(file)", f"line {exc.lineno}", f"malformed JSON: {exc.msg}"
        ) from exc
    except RecursionError:
        raise ScenarioError(file, "(file)", "(file)", f"malformed JSON: {too_deep()}") from None
    _check_depth(file, data)
    if not isinstance(data, dict) or not ({"operations", "geofences"} & set(data)):
        raise ScenarioError(
            file, "(top level)", "operations", "expected a GAUSS operations or geofences JSON"
        )
    return data


def _check_depth(file: str, data: object) -> None:
    problem = nesting_problem(data)
    if problem is not None:
        raise ScenarioError(file, "(file)", "(file)", problem)


def _read_yaml(path: Path) -> dict[str, Any]:
    file = str(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ScenarioError(file, "(file)", "(file)", "the file does not exist") from exc
    except IsADirectoryError as exc:
        raise ScenarioError(file, "(file)", "(file)", "is a directory, not a file") from exc
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "(syntax)"
        raise ScenarioError(file, "(file)", where, f"malformed YAML: {exc}") from exc
    except RecursionError:
        raise ScenarioError(file, "(file)", "(file)", f"malformed YAML: {too_deep()}") from None
    _check_depth(file, data)
    if not isinstance(data, dict):
        raise ScenarioError(file, "(top level)", "(file)", "expected a mapping")
    return data


def gauss_json_of(yaml_path: str | Path) -> Path:
    """The JSON a GAUSS YAML describes: its ``operations_json`` (else its ``geofences_json``),
    a name without suffix in the YAML's folder, as GAUSS's launch files resolve it."""
    ypath = Path(yaml_path)
    params = _read_yaml(ypath)
    for key in ("operations_json", "geofences_json"):
        name = params.get(key)
        if name is None:
            continue
        if not isinstance(name, str) or not name or "/" in name or "\\" in name:
            raise ScenarioError(
                str(ypath), "(top level)", key, f"expected a file name without folder, got {name!r}"
            )
        jpath = ypath.with_name(f"{name}.json")
        if not jpath.is_file():
            raise ScenarioError(
                str(ypath), "(top level)", key, f"names {jpath.name}, which does not exist"
            )
        return jpath
    raise ScenarioError(
        str(ypath),
        "(top level)",
        "operations_json",
        "missing; a GAUSS scenario YAML names its operations_json or geofences_json",
    )


def _num(file: str, item: str, field: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ScenarioError(file, item, field, f"expected a number, got {value!r}")
    f = float(value)
    if not math.isfinite(f):
        raise ScenarioError(file, item, field, f"expected a finite number, got {value!r}")
    return f


def _get(file: str, item: str, data: Any, field: str) -> Any:
    if not isinstance(data, dict) or field not in data:
        raise ScenarioError(file, item, field, "missing")
    return data[field]


def load_gauss(
    json_path: str | Path, yaml_path: str | Path | None = None, *, t0_s: float = 0.0
) -> Scenario:
    """Load a GAUSS scenario. ``yaml_path`` defaults to the JSON's name with ``.yaml``.

    The JSON may be an operations file (its geofences then come from the YAML's
    ``geofences_json`` in the same folder) or a geofences file (its operations then come from
    the YAML's ``operations_json``). A referenced file that is absent is logged and treated as
    empty: the paper's master branch names a ``no_geofences`` file it does not ship.
    """
    jpath = Path(json_path)
    ypath = Path(yaml_path) if yaml_path is not None else jpath.with_suffix(".yaml")
    if not ypath.exists():
        raise ScenarioError(
            str(jpath),
            "(file)",
            "yaml_path",
            f"no YAML with the origin: {ypath} does not exist; pass it explicitly",
        )
    yfile = str(ypath)
    params = _read_yaml(ypath)
    lat0 = _num(
        yfile,
        "(top level)",
        "origin_latitude",
        _get(yfile, "(top level)", params, "origin_latitude"),
    )
    lon0 = _num(
        yfile,
        "(top level)",
        "origin_longitude",
        _get(yfile, "(top level)", params, "origin_longitude"),
    )
    h0 = _num(
        yfile,
        "(top level)",
        "origin_ellipsoidal_height",
        params.get("origin_ellipsoidal_height", 0.0),
    )
    try:
        frame = LocalFrame(lat0, lon0, h0)
    except (FrameError, ValueError) as exc:
        raise ScenarioError(yfile, "(top level)", "origin_latitude", str(exc)) from exc

    main = _read_json(jpath, str(jpath))
    ops_doc: tuple[str, dict[str, Any]] | None = None
    fences_doc: tuple[str, dict[str, Any]] | None = None
    if "operations" in main:
        ops_doc = (str(jpath), main)
        ref = params.get("geofences_json")
        ref_path = jpath.with_name(f"{ref}.json") if isinstance(ref, str) and ref else None
    else:
        fences_doc = (str(jpath), main)
        ref = params.get("operations_json")
        ref_path = jpath.with_name(f"{ref}.json") if isinstance(ref, str) and ref else None
    if ref_path is not None and ref_path != jpath:
        if ref_path.exists():
            other = _read_json(ref_path, str(ref_path))
            if ops_doc is None:
                ops_doc = (str(ref_path), other)
            else:
                fences_doc = (str(ref_path), other)
        else:
            _log.warning("%s names %s, which is absent: loading none from it", yfile, ref_path)

    try:
        operations, vehicles = _operations(ops_doc, frame, t0_s, params, yfile)
        geofences = _geofences(fences_doc, frame, t0_s)
    except ModelError as exc:
        raise ScenarioError(str(jpath), exc.item, exc.field_name, exc.message) from exc
    events = _events(params, yfile, operations, t0_s)
    ends = [op.plan.end_t_s - t0_s for op in operations]
    delays = [v.start_delay_s for v in vehicles]
    duration = max([*ends, *(e.at_s for e in events), 1.0]) + max([0.0, *delays])
    sep_raw = params.get("safetyDistance")
    sep = None if sep_raw is None else _num(yfile, "(top level)", "safetyDistance", sep_raw)
    if sep is not None and sep <= 0.0:
        raise ScenarioError(yfile, "(top level)", "safetyDistance", f"must be > 0, got {sep}")
    return Scenario(
        name=jpath.stem,
        description=(
            f"GAUSS scenario {jpath.name} with {ypath.name}"
            + (f"; GAUSS safetyDistance {sep} m" if sep is not None else "")
        ),
        duration_s=float(duration),
        t0_s=t0_s,
        frame=frame,
        operations=tuple(operations),
        geofences=tuple(geofences),
        events=tuple(events),
        vehicles=tuple(vehicles),
        source=str(jpath),
        safety_distance_m=sep,
    )


def _enu_points(
    frame: LocalFrame, xs: list[float], ys: list[float], zs: list[float]
) -> list[Position]:
    lat, lon, alt = frame.enu_to_wgs84(np.array(xs), np.array(ys), np.array(zs))
    return [
        Position(lat_deg=float(a), lon_deg=float(b), alt_amsl_m=float(c))
        for a, b, c in zip(np.atleast_1d(lat), np.atleast_1d(lon), np.atleast_1d(alt), strict=True)
    ]


def _xyz(
    file: str, item: str, wps: Any, field: str
) -> tuple[list[float], list[float], list[float], list[float]]:
    if not isinstance(wps, list):
        raise ScenarioError(file, item, field, "expected a list of waypoints")
    xs, ys, zs, ts = [], [], [], []
    for j, w in enumerate(wps):
        f = f"{field}[{j}]"
        xs.append(_offset(file, item, f + ".x", _get(file, item, w, "x")))
        ys.append(_offset(file, item, f + ".y", _get(file, item, w, "y")))
        zs.append(_height(file, item, f + ".z", w.get("z", 0.0)))
        ts.append(_num(file, item, f + ".stamp", w.get("stamp", 0.0)))
    return xs, ys, zs, ts


def _offset(file: str, item: str, field: str, value: Any) -> float:
    """x or y: metres east or north of the YAML origin, within the plausibility bound."""
    v = _num(file, item, field, value)
    problem = offset_problem(v)
    if problem is not None:
        raise ScenarioError(file, item, field, problem)
    return v


def _height(file: str, item: str, field: str, value: Any) -> float:
    """z: metres above the origin; bounded as an altitude with the origin as ground."""
    v = _num(file, item, field, value)
    problem = altitude_problem(v, ground_amsl_m=0.0)
    if problem is not None:
        raise ScenarioError(file, item, field, problem)
    return v


def _operations(
    doc: tuple[str, dict[str, Any]] | None,
    frame: LocalFrame,
    t0_s: float,
    params: dict[str, Any],
    yfile: str,
) -> tuple[list[Operation], list[VehicleSetup]]:
    if doc is None:
        return [], []
    file, data = doc
    raw_ops = data.get("operations")
    if not isinstance(raw_ops, list):
        raise ScenarioError(file, "(top level)", "operations", "expected a list")
    delays: dict[str, float] = {}
    sim = params.get("simulation") or {}
    for k, entry in enumerate((sim.get("auto_start") or []) if isinstance(sim, dict) else []):
        item = f"simulation.auto_start[{k}]"
        icao = str(_get(yfile, item, entry, "icao"))
        delays[icao] = _num(yfile, item, "delay", _get(yfile, item, entry, "delay"))
    operations: list[Operation] = []
    vehicles: list[VehicleSetup] = []
    for i, raw in enumerate(raw_ops):
        item = f"operations[{i}]"
        op_id = str(_get(file, item, raw, "icao_address"))
        item = f"operations[{i}] ({op_id})"
        if any(o.id == op_id for o in operations):
            raise ScenarioError(file, item, "icao_address", f"duplicate operation {op_id}")
        try:
            icao_int = int(op_id)
        except ValueError:
            raise ScenarioError(
                file, item, "icao_address", f"expected a decimal integer, got {op_id!r}"
            ) from None
        if not 0 <= icao_int < 1 << 24:
            raise ScenarioError(file, item, "icao_address", f"{icao_int} does not fit in 24 bits")
        xs, ys, zs, ts = _xyz(
            file,
            item,
            _get(file, item, _get(file, item, raw, "flight_plan"), "waypoints"),
            "flight_plan.waypoints",
        )
        if not xs:
            raise ScenarioError(file, item, "flight_plan.waypoints", "needs at least one waypoint")
        for j in range(1, len(ts)):
            if ts[j] < ts[j - 1]:
                raise ScenarioError(
                    file,
                    item,
                    f"flight_plan.waypoints[{j}].stamp",
                    f"time goes backwards ({ts[j]} < {ts[j - 1]})",
                )
        positions = _enu_points(frame, xs, ys, zs)
        plan = FlightPlan(
            operation_id=OperationId(op_id),
            version=1,
            waypoints=tuple(
                Waypoint4D(
                    lat_deg=p.lat_deg, lon_deg=p.lon_deg, alt_amsl_m=p.alt_amsl_m, t_s=t0_s + t
                )
                for p, t in zip(positions, ts, strict=True)
            ),
            created_t_s=t0_s,
        )
        speeds = [
            math.dist((xs[j], ys[j], zs[j]), (xs[j - 1], ys[j - 1], zs[j - 1]))
            / (ts[j] - ts[j - 1])
            for j in range(1, len(xs))
            if ts[j] > ts[j - 1]
        ]
        cruise = max(speeds, default=1.0) or 1.0
        kind = (
            VehicleKind.FIXED_WING if cruise > FIXED_WING_MIN_SPEED_MPS else VehicleKind.MULTIROTOR
        )
        lxs, lys, lzs, _ = _xyz(
            file,
            item,
            (raw.get("landing_spots") or {}).get("waypoints", []),
            "landing_spots.waypoints",
        )
        sites = tuple(_enu_points(frame, lxs, lys, lzs)) if lxs else ()
        home = Position(
            lat_deg=positions[0].lat_deg,
            lon_deg=positions[0].lon_deg,
            alt_amsl_m=frame.ground_elevation_amsl_m,
        )
        geometry = _num(file, item, "flight_geometry", _get(file, item, raw, "flight_geometry"))
        volume = _num(file, item, "operational_volume", _get(file, item, raw, "operational_volume"))
        priority = raw.get("priority", 0)
        if isinstance(priority, bool) or not isinstance(priority, int):
            raise ScenarioError(file, item, "priority", f"expected an integer, got {priority!r}")
        uav_id = raw.get("uav_id")
        sys_id = SysId(uav_id + 1) if isinstance(uav_id, int) and 0 <= uav_id < 255 else None
        icao = Icao24(f"{icao_int:06x}")
        op = Operation(
            id=OperationId(op_id),
            icao24=icao,
            sys_id=sys_id,
            priority=priority,
            plan=plan,
            vehicle_kind=kind,
            cruise_speed_mps=cruise,
            flight_geometry_m=geometry,
            operational_volume_m=volume,
            conops=str(raw.get("conop", "")),
            home=home,
            landing_sites=sites,
            autopilot=Autopilot.PX4,
        )
        operations.append(op)
        vehicles.append(
            VehicleSetup(
                operation_id=op.id,
                sys_id=sys_id,
                icao24=icao,
                autopilot=Autopilot.PX4,
                vehicle_kind=kind,
                home=home,
                plan=_from_start(
                    plan,
                    frame=frame,
                    xs=xs,
                    ys=ys,
                    zs=zs,
                    ts=ts,
                    start_s=delays.get(op_id),
                    t0_s=t0_s,
                ),
                cruise_speed_mps=cruise,
                max_climb_rate_mps=op.max_climb_rate_mps,
                start_delay_s=0.0,
            )
        )
    return operations, vehicles


def _from_start(
    plan: FlightPlan,
    *,
    frame: LocalFrame,
    xs: list[float],
    ys: list[float],
    zs: list[float],
    ts: list[float],
    start_s: float | None,
    t0_s: float,
) -> FlightPlan:
    """The part of ``plan`` flown by a vehicle GAUSS starts at ``start_s`` (relative): from
    the plan's position at that time on (see the module docstring). Unchanged when the
    vehicle starts before its first stamp or no start is given; a start at or after the last
    stamp leaves the last waypoint only."""
    if start_s is None or start_s <= ts[0]:
        return plan
    if start_s >= ts[-1]:
        return replace(plan, waypoints=plan.waypoints[-1:])
    j = next(k for k in range(1, len(ts)) if ts[k] > start_s)
    u = (start_s - ts[j - 1]) / (ts[j] - ts[j - 1])
    (p,) = _enu_points(
        frame,
        [xs[j - 1] + u * (xs[j] - xs[j - 1])],
        [ys[j - 1] + u * (ys[j] - ys[j - 1])],
        [zs[j - 1] + u * (zs[j] - zs[j - 1])],
    )
    first = Waypoint4D(
        lat_deg=p.lat_deg, lon_deg=p.lon_deg, alt_amsl_m=p.alt_amsl_m, t_s=t0_s + start_s
    )
    return replace(plan, waypoints=(first, *plan.waypoints[j:]))


def _geofences(
    doc: tuple[str, dict[str, Any]] | None, frame: LocalFrame, t0_s: float
) -> list[Geofence]:
    if doc is None:
        return []
    file, data = doc
    raw_fences = data.get("geofences")
    if not isinstance(raw_fences, list):
        raise ScenarioError(file, "(top level)", "geofences", "expected a list")
    out: list[Geofence] = []
    for i, raw in enumerate(raw_fences):
        gid = str(_get(file, f"geofences[{i}]", raw, "id"))
        item = f"geofences[{i}] ({gid})"
        if any(g.id == gid for g in out):
            raise ScenarioError(file, item, "id", f"duplicate geofence id {gid}")
        lo = frame.ground_elevation_amsl_m + _height(
            file, item, "min_altitude", raw.get("min_altitude", 0.0)
        )
        hi = frame.ground_elevation_amsl_m + _height(
            file, item, "max_altitude", _get(file, item, raw, "max_altitude")
        )
        if lo > hi:
            raise ScenarioError(file, item, "min_altitude", "is above max_altitude")
        start = _num(file, item, "start_time", raw.get("start_time", 0.0))
        end = (
            _num(file, item, "end_time", raw.get("end_time", math.inf))
            if "end_time" in raw
            else None
        )
        if end is not None and start > end:
            raise ScenarioError(file, item, "start_time", "is after end_time")
        common: dict[str, Any] = {
            "id": GeofenceId(gid),
            "min_alt_amsl_m": lo,
            "max_alt_amsl_m": hi,
            "start_t_s": t0_s + start,
            "end_t_s": None if end is None else t0_s + end,
            "kind": GeofenceKind.STATIC if raw.get("static_geofence") else GeofenceKind.DYNAMIC,
            "source": file,
        }
        if raw.get("cylinder_shape", True):
            c = _get(file, item, raw, "circle")
            cx = _num(file, item, "circle.x_center", _get(file, item, c, "x_center"))
            cy = _num(file, item, "circle.y_center", _get(file, item, c, "y_center"))
            r = _num(file, item, "circle.radius", _get(file, item, c, "radius"))
            problem = radius_problem(r)
            if problem is not None:
                raise ScenarioError(file, item, "circle.radius", problem)
            cx, cy = (
                _offset(file, item, f"circle.{k}_center", v) for k, v in (("x", cx), ("y", cy))
            )
            (p,) = _enu_points(frame, [cx], [cy], [0.0])
            out.append(
                Geofence(
                    shape=GeofenceShape.CYLINDER,
                    center=LatLon(lat_deg=p.lat_deg, lon_deg=p.lon_deg),
                    radius_m=r,
                    **common,
                )
            )
        else:
            xs, ys, _zs, _ = _xyz(
                file,
                item,
                _get(file, item, _get(file, item, raw, "polygon"), "waypoints"),
                "polygon.waypoints",
            )
            pts = _enu_points(frame, xs, ys, [0.0] * len(xs))
            problem = polygon_problem([(p.lat_deg, p.lon_deg) for p in pts])
            if problem is not None:
                raise ScenarioError(file, item, "polygon", problem)
            out.append(
                Geofence(
                    shape=GeofenceShape.POLYGON,
                    vertices=tuple(LatLon(lat_deg=p.lat_deg, lon_deg=p.lon_deg) for p in pts),
                    **common,
                )
            )
    return out


def _events(
    params: dict[str, Any], yfile: str, operations: list[Operation], t0_s: float
) -> list[ScenarioEvent]:
    sim = params.get("simulation") or {}
    out: list[ScenarioEvent] = []
    ids = {o.id for o in operations}
    entries = (sim.get("change_param") or []) if isinstance(sim, dict) else []
    for k, entry in enumerate(entries):
        item = f"simulation.change_param[{k}]"
        uas = str(_get(yfile, item, entry, "icao"))
        if uas not in ids:
            raise ScenarioError(
                yfile, item, "icao", f"unknown uas {uas}; operations are {', '.join(sorted(ids))}"
            )
        at = _num(yfile, item, "delay", _get(yfile, item, entry, "delay"))
        change = _get(yfile, item, entry, "yaml")
        name = str(_get(yfile, item, change, "name"))
        if name != "jamming":
            raise ScenarioError(
                yfile, item, "yaml.name", f"unsupported parameter {name!r} (only 'jamming')"
            )
        value = _num(yfile, item, "yaml.value", _get(yfile, item, change, "value"))
        out.append(
            ScenarioEvent(
                at_s=at,
                t_s=t0_s + at,
                kind=EventKind.GNSS_JAMMING,
                uas=OperationId(uas),
                value=value,
                reason="GAUSS change_param jamming",
            )
        )
    out.sort(key=lambda e: e.at_s)
    return out
