"""Tactical Deconfliction (paper §4.5): alternatives with cost and riskiness for EM."""

from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.context import Dropped
from gcs_utm.core.deconfliction.td import TacticalDeconfliction

__all__ = ["DeconflictionConfig", "Dropped", "TacticalDeconfliction"]
