"""Builders for monitoring tests: operations and geofences from local-frame coordinates."""

from __future__ import annotations

from collections.abc import Sequence

from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Operation,
    OperationId,
    Position,
    VehicleKind,
)

FRAME = LocalFrame(37.41, -6.0, ground_elevation_amsl_m=0.0)


def latlon(e: float, n: float) -> LatLon:
    lat, lon = FRAME.point_to_wgs84(e, n)
    return LatLon(lat_deg=lat, lon_deg=lon)


def plan(op_id: str, pts: Sequence[tuple[float, float, float, float]]) -> FlightPlan:
    from gcs_utm.model import Waypoint4D

    wps = []
    for e, n, z, t in pts:
        ll = latlon(e, n)
        wps.append(Waypoint4D(lat_deg=ll.lat_deg, lon_deg=ll.lon_deg, alt_amsl_m=z, t_s=t))
    return FlightPlan(operation_id=OperationId(op_id), version=1, waypoints=tuple(wps))


def operation(
    op_id: str,
    pts: Sequence[tuple[float, float, float, float]],
    *,
    fg: float = 5.0,
    ov: float = 10.0,
    home: tuple[float, float, float] | None = None,
) -> Operation:
    h = None
    if home is not None:
        ll = latlon(home[0], home[1])
        h = Position(lat_deg=ll.lat_deg, lon_deg=ll.lon_deg, alt_amsl_m=home[2])
    return Operation(
        id=OperationId(op_id),
        icao24=None,
        sys_id=None,
        priority=1,
        plan=plan(op_id, pts),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=10.0,
        flight_geometry_m=fg,
        operational_volume_m=ov,
        home=h,
    )


def polygon(
    gid: str,
    verts: Sequence[tuple[float, float]],
    zlo: float = 0.0,
    zhi: float = 200.0,
    start: float | None = None,
    end: float | None = None,
) -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.POLYGON,
        min_alt_amsl_m=zlo,
        max_alt_amsl_m=zhi,
        vertices=tuple(latlon(e, n) for e, n in verts),
        start_t_s=start,
        end_t_s=end,
    )


def cylinder(
    gid: str,
    center: tuple[float, float],
    radius: float,
    zlo: float = 0.0,
    zhi: float = 200.0,
    start: float | None = None,
    end: float | None = None,
) -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=zlo,
        max_alt_amsl_m=zhi,
        center=latlon(*center),
        radius_m=radius,
        start_t_s=start,
        end_t_s=end,
    )
