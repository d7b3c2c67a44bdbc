"""Monitoring (paper §4.4): conformance, 4D geofences, loss of separation, intruders, and the
strategic check of filed plans. Pure: no asyncio, time, sockets or sqlite.

The names below are imported on first use (PEP 562), so importing one submodule, e.g.
``gcs_utm.core.monitoring.config``, does not import all of Monitoring."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

_HOME = {
    "MonitoringConfig": "config",
    "point_in_polygon": "geometry",
    "points_in_edges": "geometry",
    "segment_separation": "geometry",
    "Monitor": "monitor",
    "PredictionError": "separation",
    "SeparationLoss": "separation",
    "detect_los": "separation",
    "detect_los_allpairs": "separation",
    "detect_los_bruteforce": "separation",
    "detect_los_grid": "separation",
    "PlanConflict": "strategic",
    "PlanGeofenceCrossing": "strategic",
    "StrategicReport": "strategic",
    "plan_vs_geofences": "strategic",
    "plan_vs_plans": "strategic",
    "strategic_check": "strategic",
}

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


def __getattr__(name: str) -> Any:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value
    return value
