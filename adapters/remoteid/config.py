"""Settings of Remote ID (``[remote_id]``): the operator's part gcs-utm sends to each vehicle
that carries Remote ID, and the check of what vehicles broadcast. Frozen; identities are
validated on load (:mod:`adapters.remoteid.identity`). docs/remote-id.md."""

from __future__ import annotations

import math
from dataclasses import dataclass

from adapters.remoteid.identity import (
    IdentityError,
    check_operator_id,
    check_serial_number,
    parse_classification,
)
from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class OperatorLocation:
    latitude_deg: float
    longitude_deg: float
    altitude_amsl_m: float


def parse_operator_location(text: str) -> OperatorLocation:
    """``"LAT,LON,ALT_AMSL_M"`` (degrees, metres) -> :class:`OperatorLocation`."""
    parts = [p.strip() for p in text.split(",")]
    try:
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise IdentityError(
            "operator location", text, "expected LAT,LON,ALT_AMSL_M (three numbers)"
        ) from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt)):
        raise IdentityError("operator location", text, "latitude or longitude out of range")
    if lat == 0 and lon == 0:
        raise IdentityError("operator location", text, "0,0 means 'unknown' in Remote ID")
    return OperatorLocation(latitude_deg=lat, longitude_deg=lon, altitude_amsl_m=alt)


@dataclass(frozen=True, slots=True, kw_only=True)
class RemoteIdConfig:
    enabled: bool = setting(
        True,
        "send the operator's part (OPEN_DRONE_ID_SYSTEM, OPERATOR_ID, BASIC_ID) to each "
        "vehicle that declares Remote ID, and read what vehicles report",
    )
    vehicles: tuple[int, ...] = setting(
        (),
        "system ids that carry Remote ID even before they say so (otherwise a vehicle declares "
        "it with an OPEN_DRONE_ID_* message or an ArduPilot 'ODID'/'OpenDroneID' STATUSTEXT)",
    )
    system_period_s: float = setting(
        1.0,
        "period of OPEN_DRONE_ID_SYSTEM (operator location) to each vehicle; ArduPilot "
        "refuses to arm when none came for 3 s",
        min=0.1,
        max=2.5,
        unit="s",
    )
    static_period_s: float = setting(
        3.0, "period of OPEN_DRONE_ID_BASIC_ID and OPERATOR_ID to each vehicle", min=0.1, unit="s"
    )
    operator_ids: dict[str, str] = setting(
        {},
        'operator registration numbers by operation operator: {"default" = "FIN87astrdge12k8"}',
    )
    operator_locations: dict[str, str] = setting(
        {},
        'fixed operator locations by operation operator: {"default" = "LAT,LON,ALT_AMSL_M"}; '
        "otherwise the operation's home (take-off) is the operator location",
    )
    serial_numbers: dict[str, str] = setting(
        {},
        'UA serial numbers (ANSI/CTA-2063-A) by system id: {"1" = "1596A303716531B"}; sent as '
        "the vehicle's Basic ID (an ArduPilot with a serial number stored keeps its own)",
    )
    classifications: dict[str, str] = setting(
        {},
        'EU classification by system id: {"1" = "open/C1"} (category open, specific, '
        "certified or undeclared; class C0..C6 or undeclared)",
    )
    default_classification: str = setting(
        "undeclared", "classification of a vehicle not listed in classifications"
    )
    consistency_m: float = setting(
        150.0,
        "a vehicle's Remote ID location farther than this (plus its accuracy class) from its "
        "telemetry position raises a REMOTE_ID_MISMATCH threat",
        min=1.0,
        unit="m",
    )

    def __post_init__(self) -> None:
        try:
            for op_id in self.operator_ids.values():
                check_operator_id(op_id)
            for where in self.operator_locations.values():
                parse_operator_location(where)
            for key, serial in self.serial_numbers.items():
                _sysid(key, "serial_numbers")
                check_serial_number(serial)
            for key, text in self.classifications.items():
                _sysid(key, "classifications")
                parse_classification(text)
            parse_classification(self.default_classification)
        except IdentityError as exc:
            raise ValueError(str(exc)) from exc
        for sid in self.vehicles:
            if not 1 <= sid <= 255:
                raise ValueError(f"vehicles: {sid} is not a system id (1..255)")


def _sysid(key: str, table: str) -> int:
    if not key.isdigit() or not 1 <= int(key) <= 255:
        raise ValueError(f"{table}: {key!r} is not a system id (1..255)")
    return int(key)
