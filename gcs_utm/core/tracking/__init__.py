"""Tracking (paper §4.3): Kalman tracks of every UAS and intruder, current waypoint, 4D
prediction. Pure core: time is passed in; see :mod:`.tracker` for the rules."""

from gcs_utm.core.tracking.config import TrackingConfig
from gcs_utm.core.tracking.plans import PlanTable, current_waypoint
from gcs_utm.core.tracking.tracker import IngestStats, Tracker

__all__ = ["IngestStats", "PlanTable", "Tracker", "TrackingConfig", "current_waypoint"]
