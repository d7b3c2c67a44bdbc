"""Emergency Management (paper §4.4): per-threat policy, joint selection, recommendations."""

from gcs_utm.core.emergency.config import ACTIONS, DEFAULT_POLICY, EmergencyConfig
from gcs_utm.core.emergency.decision import Decision
from gcs_utm.core.emergency.manager import EmergencyManager
from gcs_utm.core.emergency.selection import Selection, select_joint

__all__ = [
    "ACTIONS",
    "DEFAULT_POLICY",
    "Decision",
    "EmergencyConfig",
    "EmergencyManager",
    "Selection",
    "select_joint",
]
