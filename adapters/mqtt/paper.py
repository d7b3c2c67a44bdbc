"""Conversion between the paper's original MQTT messages (GAUSS project templates, Capitán et
al. 2021 §5.2) and the gcs-utm v1 message set. Pure functions on JSON-like dicts.

Mapping (paper -> v1; the paper's times are milliseconds UTC, ours POSIX seconds; the full
table is in docs/mqtt.md):

- RPA_STATE_INFO -> rpa_state: icao->icao24; latitude/longitude/altitude -> lat_deg/lon_deg/
  alt_amsl_m; yaw/pitch/roll -> *_deg; groundspeed -> ground_speed_mps; covariance_h/v ->
  covariance_h_m2/v_m2; hpl hal hpe vpl val vpe -> gnss.*_m; solution_mode, jamming, spoofing,
  anomalous_clock_drift, anomalous_pos_drift -> gnss.*; signal_noise_ratio -> gnss.cn0_dbhz;
  received_power -> gnss.received_power_dbm; timestamp(ms) -> t_s.
- ADSB_SURVEILLANCE -> adsb: heading -> heading_deg, speed -> ground_speed_mps, rest as above.
- RPS_CHANGE_FLIGHT_STATUS -> flight_status: flight_plan_id -> operation_id, status -> start|stop.
- RPS_FLIGHT_PLAN_ACCEPT -> pilot_answer: flight_plan_id -> recommendation_id, accept ->
  decision. The paper has NO version: the caller supplies the version the pilot was shown.
- GCS_FLIGHT_PLAN -> flight_plan: WKT LINESTRING(lon lat alt, ...) -> waypoints; the paper has
  no times: they follow from a start time and a ground speed.
- AIRSPACE_UPDATE -> airspace_alert: id -> alert_id, type -> category, state -> region,
  last_updated -> t_s, date_effective -> start_t_s, CIRCLE(lat, lon, radius_m) or
  POLYGON((lon lat, ...)) -> geometry; no altitude band in the paper: the caller's.
- alert -> UTM_ALERT, recommendation -> UTM_ALTERNATIVE_FLIGHT_PLAN ([lon, lat, alt, t_s]
  list), geofence -> UTM_GEOFENCE_CREATION (circles only): for legacy consumers.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from adapters.mqtt.codec import SCHEMA_VERSION

_EARTH_RADIUS_M = 6_371_008.8  # mean Earth radius (IUGG); plan timing only needs ~0.5 %

_ALERT_CATEGORIES = frozenset({"wildfire", "weather", "restriction", "emergency"})
_START = frozenset({"start", "started", "begin", "takeoff", "active", "flying"})
_STOP = frozenset({"stop", "stopped", "end", "ended", "finished", "landed", "cancelled"})


class PaperFormatError(ValueError):
    """A paper-format message that cannot be converted: ``field`` and ``reason``."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


def _icao(value: object) -> str:
    if isinstance(value, bool):
        raise PaperFormatError("icao", "expected an integer or 6 hex digits")
    if isinstance(value, int):
        if not 0 <= value < 1 << 24:
            raise PaperFormatError("icao", f"{value} is not a 24-bit address")
        return f"{value:06x}"
    return str(value).strip().lower().removeprefix("0x")


def _ms(obj: Mapping[str, Any], key: str) -> float:
    try:
        return float(obj[key]) / 1000.0
    except (KeyError, TypeError, ValueError) as exc:
        raise PaperFormatError(key, "expected a time in milliseconds UTC") from exc


def _header(t: str) -> dict[str, Any]:
    return {"schema_version": SCHEMA_VERSION, "type": t}


def _copy(src: Mapping[str, Any], dst: dict[str, Any], pairs: Mapping[str, str]) -> None:
    for old, new in pairs.items():
        if src.get(old) is not None:
            dst[new] = src[old]


def rpa_state_from_paper(p: Mapping[str, Any]) -> dict[str, Any]:
    out = _header("rpa_state")
    out["icao24"] = _icao(p.get("icao"))
    out["t_s"] = _ms(p, "timestamp")
    _copy(
        p,
        out,
        {
            "latitude": "lat_deg",
            "longitude": "lon_deg",
            "altitude": "alt_amsl_m",
            "yaw": "yaw_deg",
            "pitch": "pitch_deg",
            "roll": "roll_deg",
            "groundspeed": "ground_speed_mps",
            "covariance_h": "covariance_h_m2",
            "covariance_v": "covariance_v_m2",
        },
    )
    gnss: dict[str, Any] = {}
    _copy(
        p,
        gnss,
        {
            "hpl": "hpl_m",
            "hal": "hal_m",
            "hpe": "hpe_m",
            "vpl": "vpl_m",
            "val": "val_m",
            "vpe": "vpe_m",
            "signal_noise_ratio": "cn0_dbhz",
            "received_power": "received_power_dbm",
        },
    )
    if p.get("solution_mode") is not None:
        gnss["solution_mode"] = str(p["solution_mode"])
    for flag in ("jamming", "spoofing", "anomalous_clock_drift", "anomalous_pos_drift"):
        if p.get(flag) is not None:
            gnss[flag] = bool(p[flag])
    if gnss:
        out["gnss"] = gnss
    return out


def adsb_from_paper(p: Mapping[str, Any]) -> dict[str, Any]:
    out = _header("adsb")
    out["icao24"] = _icao(p.get("icao"))
    out["t_s"] = _ms(p, "timestamp")
    _copy(
        p,
        out,
        {
            "callsign": "callsign",
            "latitude": "lat_deg",
            "longitude": "lon_deg",
            "altitude": "alt_amsl_m",
            "heading": "heading_deg",
            "speed": "ground_speed_mps",
        },
    )
    return out


def flight_status_from_paper(p: Mapping[str, Any]) -> dict[str, Any]:
    status = str(p.get("status", "")).strip().lower()
    if status in _START:
        status = "start"
    elif status in _STOP:
        status = "stop"
    else:
        raise PaperFormatError("status", f"unknown flight status {p.get('status')!r}")
    out = _header("flight_status")
    out["operation_id"] = str(p.get("flight_plan_id", ""))
    out["status"] = status
    out["t_s"] = _ms(p, "timestamp")
    if p.get("icao") is not None:
        out["icao24"] = _icao(p["icao"])
    return out


def pilot_answer_from_paper(p: Mapping[str, Any], *, version: int, t_s: float) -> dict[str, Any]:
    """``version``: the recommendation version the pilot was shown (the paper omits it)."""
    accept = p.get("accept")
    if isinstance(accept, str):
        accept = accept.strip().lower() in {"true", "1", "yes", "accept"}
    if not isinstance(accept, bool | int):
        raise PaperFormatError("accept", "expected a boolean")
    out = _header("pilot_answer")
    out.update(
        recommendation_id=str(p.get("flight_plan_id", "")),
        version=version,
        decision="accept" if accept else "reject",
        t_s=t_s,
    )
    return out


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dp, dl = p2 - p1, math.radians(lon2 - lon1)
    a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * _EARTH_RADIUS_M * math.asin(math.sqrt(a))


def flight_plan_from_paper(
    p: Mapping[str, Any],
    *,
    operation_id: str,
    start_t_s: float,
    ground_speed_mps: float,
) -> dict[str, Any]:
    """The paper's plan is a WKT ``LINESTRING(lon lat alt, ...)`` without times: waypoint
    times follow from ``start_t_s`` and a constant ``ground_speed_mps`` (3D distance)."""
    text = str(p.get("waypoints", ""))
    m = re.fullmatch(r"\s*LINESTRING\s*Z?\s*\((.*)\)\s*", text, flags=re.IGNORECASE)
    if m is None:
        raise PaperFormatError("waypoints", "expected WKT LINESTRING(lon lat alt, ...)")
    if not ground_speed_mps > 0:
        raise PaperFormatError("ground_speed_mps", "must be positive")
    waypoints: list[dict[str, float]] = []
    t_s = start_t_s
    for i, chunk in enumerate(m.group(1).split(",")):
        nums = re.findall(_NUM, chunk)
        if len(nums) != 3:
            raise PaperFormatError(f"waypoints[{i}]", f"expected 'lon lat alt', got {chunk!r}")
        lon, lat, alt = (float(v) for v in nums)
        if waypoints:
            prev = waypoints[-1]
            d_h = _distance_m(prev["lat_deg"], prev["lon_deg"], lat, lon)
            t_s += math.hypot(d_h, alt - prev["alt_amsl_m"]) / ground_speed_mps
        waypoints.append({"lat_deg": lat, "lon_deg": lon, "alt_amsl_m": alt, "t_s": t_s})
    out = _header("flight_plan")
    out.update(operation_id=operation_id, t_s=start_t_s, waypoints=waypoints)
    if p.get("icao") is not None:
        out["icao24"] = _icao(p["icao"])
    out["cruise_speed_mps"] = ground_speed_mps
    return out


def airspace_alert_from_paper(
    p: Mapping[str, Any], *, min_alt_amsl_m: float = 0.0, max_alt_amsl_m: float = 10_000.0
) -> dict[str, Any]:
    """``CIRCLE(lat, lon, radius_m)`` (the paper's order: latitude first) or WKT
    ``POLYGON((lon lat, ...))``. The paper has no altitude band; the default is 0..10 km AMSL
    (a wildfire closes everything above it)."""
    text = str(p.get("geometry", "")).strip()
    geometry: dict[str, Any]
    circle = re.fullmatch(rf"CIRCLE\s*\(\s*({_NUM})\s*,\s*({_NUM})\s*,\s*({_NUM})\s*\)", text, re.I)
    polygon = re.fullmatch(r"POLYGON\s*\(\s*\((.*)\)\s*\)", text, re.I)
    if circle is not None:
        lat, lon, radius = (float(v) for v in circle.groups())
        geometry = {
            "shape": "circle",
            "center": {"lat_deg": lat, "lon_deg": lon},
            "radius_m": radius,
        }
    elif polygon is not None:
        vertices = []
        for chunk in polygon.group(1).split(","):
            nums = re.findall(_NUM, chunk)
            if len(nums) < 2:
                raise PaperFormatError("geometry", f"bad polygon vertex {chunk!r}")
            vertices.append({"lat_deg": float(nums[1]), "lon_deg": float(nums[0])})
        if len(vertices) > 3 and vertices[0] == vertices[-1]:
            vertices.pop()  # WKT repeats the first vertex to close the ring
        geometry = {"shape": "polygon", "vertices": vertices}
    else:
        raise PaperFormatError("geometry", "expected CIRCLE(lat, lon, radius) or POLYGON((...))")
    category = str(p.get("type", "")).strip().lower()
    out = _header("airspace_alert")
    out.update(
        alert_id=str(p.get("id", "")),
        name=str(p.get("name", "")),
        category=category if category in _ALERT_CATEGORIES else "other",
        t_s=_ms(p, "last_updated"),
        geometry=geometry,
        min_alt_amsl_m=min_alt_amsl_m,
        max_alt_amsl_m=max_alt_amsl_m,
    )
    if p.get("date_effective") is not None:
        out["start_t_s"] = _ms(p, "date_effective")
    _copy(p, out, {"country": "country", "state": "region", "city": "city"})
    return out


def alert_to_paper(alert: Mapping[str, Any], *, icao: str) -> dict[str, Any]:
    pos = alert.get("position")
    return {
        "icao": icao,
        "alert_title": alert["kind"],
        "alert_id": alert["alert_id"],
        "alert_message": alert["message"],
        "alert_wp": None if pos is None else [pos["lon_deg"], pos["lat_deg"], pos["alt_amsl_m"]],
    }


def recommendation_to_paper(rec: Mapping[str, Any], *, icao: str) -> dict[str, Any]:
    selected = rec.get("selected") or {"waypoints": []}
    return {
        "icao": icao,
        "flight_plan_id": rec["recommendation_id"],
        "new_flight_plan": [
            [w["lon_deg"], w["lat_deg"], w["alt_amsl_m"], w["t_s"]] for w in selected["waypoints"]
        ],
    }


def geofence_to_paper(g: Mapping[str, Any], *, confidence: float = 1.0) -> dict[str, Any]:
    geometry = g["geometry"]
    if geometry["shape"] != "circle":
        raise PaperFormatError("geometry", "the paper's geofence message carries circles only")
    return {
        "uuid": g["id"],
        "longitude": geometry["center"]["lon_deg"],
        "latitude": geometry["center"]["lat_deg"],
        "circle_radius": geometry["radius_m"],
        "start_altitude": g["min_alt_amsl_m"],
        "end_altitude": g["max_alt_amsl_m"],
        "start_time": g.get("start_t_s"),
        "finish_time": g.get("end_t_s"),
        "confidence": confidence,
        "description": g.get("reason", ""),
    }
