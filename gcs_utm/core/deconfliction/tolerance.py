"""The tracking tolerances TD keeps free between two new plans (see
:func:`.context.pair_minima`): each vehicle flies a new plan with a
horizontal lag at its corners and a vertical error (altitude hold, a climb reached late),
so the pair's minima are widened by both vehicles' tolerances, horizontally and vertically
alike. Pure."""

from __future__ import annotations

from gcs_utm.envelope import PerformanceEnvelope


def pair_buffers(
    a: PerformanceEnvelope,
    b: PerformanceEnvelope,
    horizontal_m: float,
    vertical_m: float,
    spherical: bool,
) -> tuple[float, float]:
    """(horizontal, vertical) minima plus the sum of both envelopes' tracking tolerances on
    each axis. In sphere mode the single 3D distance (``horizontal_m``) takes the horizontal
    tolerances, as the vertical minimum does not apply there."""
    h_buf = a.tracking_tolerance_m() + b.tracking_tolerance_m()
    if spherical:
        return horizontal_m + h_buf, vertical_m + h_buf
    v_buf = a.vertical_tracking_tolerance_m() + b.vertical_tracking_tolerance_m()
    return horizontal_m + h_buf, vertical_m + v_buf
