"""Monitoring (paper §4.4): conformance, 4D geofences, loss of separation, intruders, and the
strategic check of filed plans. Pure: no asyncio, time, sockets or sqlite."""

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.geometry import (
    point_in_polygon,
    points_in_edges,
    segment_separation,
)
from gcs_utm.core.monitoring.monitor import Monitor
from gcs_utm.core.monitoring.separation import (
    PredictionError,
    SeparationLoss,
    detect_los,
    detect_los_allpairs,
    detect_los_bruteforce,
    detect_los_grid,
)
from gcs_utm.core.monitoring.strategic import (
    PlanConflict,
    PlanGeofenceCrossing,
    StrategicReport,
    plan_vs_geofences,
    plan_vs_plans,
    strategic_check,
)

__all__ = [
    "Monitor",
    "MonitoringConfig",
    "PlanConflict",
    "PlanGeofenceCrossing",
    "PredictionError",
    "SeparationLoss",
    "StrategicReport",
    "detect_los",
    "detect_los_allpairs",
    "detect_los_bruteforce",
    "detect_los_grid",
    "plan_vs_geofences",
    "plan_vs_plans",
    "point_in_polygon",
    "points_in_edges",
    "segment_separation",
    "strategic_check",
]
