"""Prediction of track rows over the horizon (see :meth:`.tracker.Tracker.predict`): each
function takes the rows' filter state and returns one (N, K) array per axis (east, north,
alt) and the (N, K) radius [m]. ``ahead0`` is each row's time from its state to the first
point [s], ``steps`` the points' offsets from the first [s]."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from gcs_utm.core.tracking import kalman
from gcs_utm.core.tracking.config import TrackingConfig
from gcs_utm.core.tracking.plans import PlanTable

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


def extrapolate(
    x: FloatArray, p: FloatArray, q: FloatArray, ahead0: FloatArray, steps: FloatArray
) -> tuple[list[FloatArray], FloatArray]:
    """Rows ``x`` (N, 3, 2), ``p`` (N, 3, 3) extrapolated with the filter's velocity; the
    radius is the root of the trace of the propagated position covariance (process noise
    ``q`` (3,))."""
    tau = np.add.outer(ahead0, steps)
    axes = [x[:, axis, kalman.POS, None] + x[:, axis, kalman.VEL, None] * tau for axis in range(3)]
    pp = p[:, :, kalman.PP].sum(axis=1)[:, None]
    pv = p[:, :, kalman.PV].sum(axis=1)[:, None]
    vv = p[:, :, kalman.VV].sum(axis=1)[:, None]
    var = kalman.propagated_pp(pp, pv, vv, float(q.sum()), tau)
    return axes, np.sqrt(var)


def follow(  # noqa: PLR0917 (the rows' state and plans, as extrapolate)
    plans: PlanTable,
    cfg: TrackingConfig,
    x: FloatArray,
    p: FloatArray,
    plan_rows: IntArray,
    tau0: FloatArray,
    a0: FloatArray,
    steps: FloatArray,
) -> tuple[list[FloatArray], FloatArray]:
    """Rows ``x``, ``p`` following plans ``plan_rows`` from plan times ``tau0``: the plan
    positions plus the current cross-track offset decaying as exp(-(a0 + k step) / T); the
    radius grows linearly with time from the state."""
    k = len(steps)
    now = plans.follow(plan_rows, tau0, np.zeros(len(plan_rows)), 1.0, 1)
    axes = list(plans.follow(plan_rows, tau0, a0, cfg.step_s, k))
    # The decay is an outer product of two vectors (no (N, K) exp), added in place.
    decay_t = cfg.plan_offset_decay_s
    decay_k = np.exp(-steps / decay_t)
    decay_0 = np.exp(-a0 / decay_t)
    # A snapshot older than the track (a0 < 0) must not amplify the offset: those few rows
    # use exp(-max(a0 + k step, 0) / T) instead.
    young = np.flatnonzero(a0 < 0.0)
    capped = np.exp(-np.maximum(np.add.outer(a0[young], steps), 0.0) / decay_t)
    for axis in range(3):
        offset = x[:, axis, kalman.POS] - now[axis][:, 0]
        value = axes[axis]
        plain = value[young]
        value += np.multiply.outer(offset * decay_0, decay_k)
        value[young] = plain + offset[young, None] * capped
    # sqrt(pp + (growth * (a0 + k step))^2), in place on one (N, K) array.
    sigma = np.add.outer(a0, steps)
    sigma *= cfg.plan_sigma_growth_mps
    sigma *= sigma
    sigma += p[:, :, kalman.PP].sum(axis=1)[:, None]
    np.sqrt(sigma, out=sigma)
    return axes, sigma
