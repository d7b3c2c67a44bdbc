"""The one definition of a loss of separation between two UAS, used by Monitoring, Tactical
Deconfliction, Emergency Management and the run report.

A pair of UAS with operational-volume radii ``ov_a_m`` and ``ov_b_m`` has the *effective
minima* ``MonitoringConfig.effective_minima``: the configured horizontal/vertical minima (or
the 3D safety distance in sphere mode), never less than ``ov_a_m + ov_b_m`` (two operational
volumes that touch are already a loss). At one instant, with horizontal distance ``dh_m`` and
vertical distance ``dv_m``:

- cylinder mode: loss iff ``dh_m < h_min_m`` **and** ``dv_m < v_min_m``;
- sphere mode: loss iff ``hypot(dh_m, dv_m) < safety distance``.

Equality is separated (the inequalities are strict, as in Monitoring's closed-form segment
test). :func:`separation_ratio` is the same rule as a number: below 1 is a loss; a resolution
that keeps ``(1 + margin)`` times the minima keeps the ratio at or above ``1 + margin``.
"""

from __future__ import annotations

import numpy as np

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import FloatArray

ArrayOrFloat = FloatArray | float


def minima_arrays(
    config: MonitoringConfig, ov_a_m: FloatArray, ov_b_m: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``config.effective_minima`` for arrays of operational-volume radii (metres)."""
    floor = ov_a_m + ov_b_m  # m
    if config.spherical:
        s = np.maximum(config.safety_distance_m, floor)
        return s, s
    return (
        np.maximum(config.separation_horizontal_m, floor),
        np.maximum(config.separation_vertical_m, floor),
    )


def separation_ratio(
    dh_m: ArrayOrFloat,
    dv_m: ArrayOrFloat,
    h_min_m: ArrayOrFloat,
    v_min_m: ArrayOrFloat,
    *,
    spherical: bool,
) -> FloatArray:
    """How many times the minima apart: ``max(dh/h_min, |dv|/v_min)`` (cylinder) or
    ``hypot(dh, dv)/h_min`` (sphere, where ``h_min_m`` is the safety distance). A ratio
    below 1 is a loss of separation."""
    dh = np.asarray(dh_m, dtype=np.float64)
    dv = np.abs(np.asarray(dv_m, dtype=np.float64))
    if spherical:
        out: FloatArray = np.hypot(dh, dv) / h_min_m
        return out
    out = np.maximum(dh / h_min_m, dv / v_min_m)
    return out
