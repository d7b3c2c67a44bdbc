"""Read sitl's own fleet TOML into VehicleSpecs (validated; unknown keys are errors).

Format (see docs/sitl.md):

    speed = 1.0                 # optional, PX4_SIM_SPEED_FACTOR-like
    start_utc_s = 1700000000.0  # optional, simulated UTC at start (default: now)

    [defaults]                  # optional, any vehicle key
    gcs_port = 14550

    [[vehicle]]
    instance = 0
    kind = "multirotor"         # or "fixed_wing"
    home = [47.3977, 8.5456, 488.0]
    auto_start_at_s = 5.0
    signing_key = "<64 hex digits>"  # optional: enforce MAVLink 2 signing (see VehicleSpec)
    # lat, lon, alt AMSL[, speed]
    mission = [[47.3985, 8.5456, 510.0], [47.3985, 8.5470, 510.0, 6.0]]
    faults = [{ kind = "gnss_jamming", at_s = 30.0, duration_s = 20.0, value = 2.0 }]
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

from sitl.spec import FaultKind, FaultSpec, MissionItemSpec, VehicleSpec


class FleetFileError(ValueError):
    def __init__(self, path: str, key: str, expected: str) -> None:
        super().__init__(f"{path}: key {key!r}: expected {expected}")
        self.path = path
        self.key = key
        self.expected = expected


_SPEC_FIELDS = {f.name: f for f in dataclasses.fields(VehicleSpec)}
_TOP_KEYS = {"speed", "start_utc_s", "defaults", "vehicle"}


def _num(path: str, key: str, v: object) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise FleetFileError(path, key, "a number")
    return float(v)


def _mission(path: str, key: str, v: object) -> tuple[MissionItemSpec, ...]:
    if not isinstance(v, list):
        raise FleetFileError(path, key, "a list of [lat, lon, alt_amsl(, speed)]")
    out = []
    for i, wp in enumerate(v):
        k = f"{key}[{i}]"
        if isinstance(wp, dict):
            try:
                out.append(MissionItemSpec(**{n: _num(path, f"{k}.{n}", x) for n, x in wp.items()}))
            except TypeError as exc:
                raise FleetFileError(
                    path, k, "lat_deg, lon_deg, alt_amsl_m, speed_mps, acceptance_radius_m"
                ) from exc
            continue
        if not isinstance(wp, list) or len(wp) not in (3, 4):
            raise FleetFileError(path, k, "[lat_deg, lon_deg, alt_amsl_m] or with speed_mps")
        nums = [_num(path, k, x) for x in wp]
        out.append(
            MissionItemSpec(
                lat_deg=nums[0],
                lon_deg=nums[1],
                alt_amsl_m=nums[2],
                speed_mps=nums[3] if len(nums) == 4 else None,
            )
        )
    return tuple(out)


def _faults(path: str, key: str, v: object) -> tuple[FaultSpec, ...]:
    if not isinstance(v, list):
        raise FleetFileError(path, key, "a list of {kind, at_s, duration_s, value} tables")
    out = []
    kinds = {k.value: k for k in FaultKind}
    for i, f in enumerate(v):
        k = f"{key}[{i}]"
        if not isinstance(f, dict) or set(f) - {"kind", "at_s", "duration_s", "value"}:
            raise FleetFileError(path, k, "a table with kind, at_s, duration_s, value")
        kind = kinds.get(str(f.get("kind")))
        if kind is None:
            raise FleetFileError(path, k + ".kind", "one of " + ", ".join(sorted(kinds)))
        dur = f.get("duration_s")
        val = f.get("value")
        out.append(
            FaultSpec(
                kind=kind,
                at_s=_num(path, k + ".at_s", f.get("at_s", 0.0)),
                duration_s=None if dur is None else _num(path, k + ".duration_s", dur),
                value=None if val is None else _num(path, k + ".value", val),
            )
        )
    return tuple(out)


def vehicle_spec(path: str, table: dict[str, Any], where: str) -> VehicleSpec:
    kw: dict[str, Any] = {}
    for key, v in table.items():
        full = f"{where}.{key}"
        if key == "home":
            if not isinstance(v, list) or len(v) != 3:
                raise FleetFileError(path, full, "[lat_deg, lon_deg, alt_amsl_m]")
            kw["home_lat_deg"], kw["home_lon_deg"], kw["home_alt_amsl_m"] = (
                _num(path, full, x) for x in v
            )
        elif key == "mission":
            kw["mission"] = _mission(path, full, v)
        elif key == "faults":
            kw["faults"] = _faults(path, full, v)
        elif key == "stream_rates_hz":
            if not isinstance(v, dict):
                raise FleetFileError(path, full, "a table of MESSAGE_NAME = Hz")
            kw[key] = tuple((str(n), _num(path, f"{full}.{n}", r)) for n, r in v.items())
        elif key in _SPEC_FIELDS:
            kw[key] = v
        else:
            raise FleetFileError(path, full, "a VehicleSpec field (see docs/sitl.md)")
    if "instance" not in kw:
        raise FleetFileError(path, f"{where}.instance", "an integer")
    try:
        return VehicleSpec(**kw)
    except (TypeError, ValueError) as exc:
        raise FleetFileError(path, where, str(exc)) from exc


def load_fleet(path: str | Path) -> tuple[list[VehicleSpec], float, float | None]:
    """Return (specs, speed, start_utc_s) from a fleet TOML file."""
    p = str(path)
    with open(path, "rb") as fh:
        doc = tomllib.load(fh)
    for key in doc:
        if key not in _TOP_KEYS:
            raise FleetFileError(p, key, "one of " + ", ".join(sorted(_TOP_KEYS)))
    speed = _num(p, "speed", doc.get("speed", 1.0))
    start = doc.get("start_utc_s")
    start_utc = None if start is None else _num(p, "start_utc_s", start)
    defaults = doc.get("defaults", {})
    if not isinstance(defaults, dict):
        raise FleetFileError(p, "defaults", "a table")
    vehicles = doc.get("vehicle", [])
    if not isinstance(vehicles, list) or not vehicles:
        raise FleetFileError(p, "vehicle", "one or more [[vehicle]] tables")
    specs = [vehicle_spec(p, {**defaults, **v}, f"vehicle[{i}]") for i, v in enumerate(vehicles)]
    return specs, speed, start_utc
