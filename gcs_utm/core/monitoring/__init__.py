"""Monitoring (paper §4.4): conformance, 4D geofences, loss of separation, intruders, and the
strategic check of filed plans. Pure: no asyncio, time, sockets or sqlite."""

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.geometry import point_in_polygon, segment_separation
from gcs_utm.core.monitoring.strategic import (
    PlanConflict,
    PlanGeofenceCrossing,
    StrategicReport,
    plan_vs_geofences,
    plan_vs_plans,
    strategic_check,
)

__all__ = [
    "MonitoringConfig",
    "PlanConflict",
    "PlanGeofenceCrossing",
    "StrategicReport",
    "plan_vs_geofences",
    "plan_vs_plans",
    "point_in_polygon",
    "segment_separation",
    "strategic_check",
]
