"""Shared builders for the tracking tests: a frame near Seville (the paper's test site) and
measurements given in local metres. (Not a conftest: other areas have their own helpers, and
the unique module name avoids a clash in one pytest session.)"""

from __future__ import annotations

from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Icao24,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    SysId,
    VehicleKind,
    Waypoint4D,
)

FRAME = LocalFrame(37.41, -6.0, 10.0)
T0 = 1_700_000_000.0


def new_tracker(**overrides: float) -> Tracker:
    return Tracker(FRAME, TrackingConfig(**overrides))  # type: ignore[arg-type]


def meas(
    east_m: float,
    north_m: float,
    alt_amsl_m: float,
    t_s: float,
    *,
    source: MeasurementSource = MeasurementSource.TELEMETRY,
    sys_id: int | None = 1,
    icao24: str | None = None,
    eph_m: float | None = None,
    epv_m: float | None = None,
    vel_ned_mps: tuple[float, float, float] | None = None,
) -> Measurement:
    lat, lon = FRAME.point_to_wgs84(east_m, north_m)
    return Measurement(
        source=source,
        capture_t_s=t_s,
        receipt_t_s=t_s + 0.05,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=alt_amsl_m,
        vel_ned_mps=vel_ned_mps,
        eph_m=eph_m,
        epv_m=epv_m,
        sys_id=SysId(sys_id) if sys_id is not None else None,
        icao24=Icao24(icao24) if icao24 is not None else None,
    )


def plan_from_local(op_id: str, points: list[tuple[float, float, float, float]]) -> FlightPlan:
    """(east_m, north_m, alt_amsl_m, t_s) -> FlightPlan."""
    wps = []
    for e, n, alt, t in points:
        lat, lon = FRAME.point_to_wgs84(e, n)
        wps.append(Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=alt, t_s=t))
    return FlightPlan(operation_id=OperationId(op_id), version=1, waypoints=tuple(wps))


def operation(
    op_id: str,
    plan: FlightPlan,
    *,
    sys_id: int | None = 1,
    icao24: str | None = None,
    flight_geometry_m: float = 10.0,
) -> Operation:
    return Operation(
        id=OperationId(op_id),
        icao24=Icao24(icao24) if icao24 is not None else None,
        sys_id=SysId(sys_id) if sys_id is not None else None,
        priority=1,
        plan=plan,
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=10.0,
        flight_geometry_m=flight_geometry_m,
        operational_volume_m=max(50.0, flight_geometry_m),
    )
