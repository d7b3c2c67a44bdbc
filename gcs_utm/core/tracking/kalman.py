"""Batched 3D constant-velocity Kalman filter in closed form, one row per track.

Why closed form: the model (constant velocity, white acceleration per axis, position and
optional velocity measured per axis with a diagonal noise) is separable by axis. When the
initial covariance is block-diagonal per axis -- which is how tracks are born -- it stays so
forever, and the 6-state filter is exactly three independent 2-state filters (position,
velocity). Each 2x2 step is a few array expressions over all tracks at once; no per-track
Python, no matrix inversion. The tests check every step against ``filterpy.kalman.KalmanFilter``
with the full 6x6 matrices and ``filterpy.common.Q_discrete_white_noise`` to 1e-9.

Layout (struct of arrays, N rows):
- ``x``: (N, 3, 2) per axis (east, north, up) the pair (position_m, velocity_mps);
- ``p``: (N, 3, 3) per axis the unique covariance entries (pp [m^2], pv [m^2/s], vv [m^2/s^2]).
Symmetry of the covariance holds by construction (one pv entry); positive semi-definiteness
is kept by the update formulas of :func:`step`.

The tracker stores its rows (``x`` (N, 3, 2), ``p`` (N, 3, 3)) and gathers the rows of a round
axis-major into planes for :func:`step`, ``x`` (2, 3, M) and ``p`` (3, 3, M), so that every
quantity is one contiguous (3, M) array: a small batch costs one NumPy call per arithmetic
operation, with no strided (M, 3) views (several times slower per call). :func:`step` is the
one Python implementation of the filter step; the optional C kernel (``_kalman_c.c``) is
checked against it.

Process noise: ``q`` (3,) white-acceleration variances [m^2/s^4]; for a step ``dt`` it is
``q * [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]`` -- filterpy's ``Q_discrete_white_noise(dim=2)``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

PP, PV, VV = 0, 1, 2
POS, VEL = 0, 1


def propagated_pp(
    pp: FloatArray, pv: FloatArray, vv: FloatArray, q: FloatArray | float, tau_s: FloatArray
) -> FloatArray:
    """The one propagation of the position variance: ``pp`` [m^2] after ``tau_s`` without
    updates, ``pp + 2 tau pv + tau^2 vv + q tau^4 / 4`` (the predict of :func:`step`, the
    snapshot's variances and the prediction's radius; the C kernel writes the same
    expression, in the same order)."""
    tau2 = tau_s * tau_s
    out: FloatArray = pp + 2.0 * tau_s * pv + tau2 * vv + q * (tau2 * tau2 / 4.0)
    return out


def predicted_position_var(p: FloatArray, tau_s: FloatArray, q: FloatArray) -> FloatArray:
    """Position variance per axis after ``tau_s`` without updates.

    ``p``: (N, 3, 3); ``tau_s``: (N, K); returns (N, K, 3) [m^2]."""
    return propagated_pp(
        p[:, None, :, PP], p[:, None, :, PV], p[:, None, :, VV], q, tau_s[:, :, None]
    )


def start(  # noqa: PLR0917 (the planes of a track's first measurement)
    z_m: FloatArray,
    r_m2: FloatArray,
    zv_mps: FloatArray,
    rv_m2ps2: FloatArray,
    has_vel: npt.NDArray[np.bool_],
    vel_var_m2ps2: float,
) -> tuple[FloatArray, FloatArray]:
    """The state and covariance planes, ``x`` (2, 3, M) and ``p`` (3, 3, M), of tracks that
    start from a measurement (a new track, or one restarted after a gap or a wrong first
    fix): the measured position ``z_m`` with its variance ``r_m2``; the measured velocity
    ``zv_mps`` with ``rv_m2ps2`` where ``has_vel`` (M,), else 0 with ``vel_var_m2ps2``
    (unknown: the next measurements give it); no position-velocity correlation. Planes
    (3, M) as :func:`step` takes them."""
    x = np.empty((2, 3, z_m.shape[1]))
    x[POS] = z_m
    x[VEL] = np.where(has_vel, zv_mps, 0.0)
    p = np.empty((3, 3, z_m.shape[1]))
    p[PP] = r_m2
    p[PV] = 0.0
    p[VV] = np.where(has_vel, rv_m2ps2, vel_var_m2ps2)
    return x, p


def step(  # noqa: PLR0917 (the arrays of one filter step, as the other functions)
    x: FloatArray,
    p: FloatArray,
    dt_s: FloatArray,
    q: FloatArray,
    z_m: FloatArray,
    r_m2: FloatArray,
    zv_mps: FloatArray | None = None,
    rv_m2ps2: FloatArray | None = None,
    *,
    positions_predicted: bool = False,
) -> None:
    """One predict-then-update step, in place, on planes: ``x`` (2, 3, M) positions and
    velocities, ``p`` (3, 3, M) pp, pv, vv; ``dt_s`` (M,); ``q`` (3, 1); ``z_m``, ``r_m2``,
    ``zv_mps``, ``rv_m2ps2`` (3, M). ``positions_predicted``: the caller already moved the
    positions by ``vel * dt_s`` (it needed them to gate). Every operand has the same shape
    (broadcasting costs a small batch more than the arithmetic).

    Position only (``zv_mps is None``), per axis: S = pp + r, K = (pp, pv) / S; the posterior
    pp' = pp r / S, pv' = pv r / S, vv' = vv - pv^2 / S has the determinant
    (r / S) (pp vv - pv^2) >= 0: positive semi-definite whenever the prior is.
    Position and velocity: S = P + diag(r, rv) (2x2), K = P S^-1, P' = K diag(r, rv), written
    out with det(S) > 0 (r, rv > 0); P' is symmetric (k12 rv = k21 r exactly) and its
    determinant det(P) r rv / det(S) >= 0. P' = K R rather than the textbook P - K P: the
    latter subtracts two nearly equal numbers when a long prediction made the prior large and
    the measurement precise (900 m^2 - 899.985 m^2), and a 1e-11 error in K became a 1e-6
    error in the state one update later."""
    pos = x[POS]
    vel = x[VEL]
    a = p[PP]
    b = p[PV]
    c = p[VV]
    dt = np.empty_like(pos)
    dt[...] = dt_s
    qq = np.empty_like(pos)
    qq[...] = q
    # predict
    dt2 = dt * dt
    a = propagated_pp(a, b, c, qq, dt)
    b = b + dt * c + qq * (dt2 * dt / 2.0)
    c = c + qq * dt2
    if not positions_predicted:
        pos += vel * dt
    if zv_mps is None:
        s = a + r_m2
        y = z_m - pos
        k_vel = b / s
        pos += a / s * y
        vel += k_vel * y
        rs = r_m2 / s
        np.subtract(c, b * k_vel, out=p[VV])
        np.multiply(a, rs, out=p[PP])
        np.multiply(b, rs, out=p[PV])
        return
    assert rv_m2ps2 is not None
    s11 = a + r_m2
    s22 = c + rv_m2ps2
    bb = b * b
    det = s11 * s22 - bb
    k11 = (a * s22 - bb) / det
    k12 = (b * s11 - a * b) / det
    k21 = (b * s22 - c * b) / det
    k22 = (c * s11 - bb) / det
    y1 = z_m - pos
    y2 = zv_mps - vel
    pos += k11 * y1 + k12 * y2
    vel += k21 * y1 + k22 * y2
    np.multiply(k11, r_m2, out=p[PP])
    np.multiply(k12, rv_m2ps2, out=p[PV])
    np.multiply(k22, rv_m2ps2, out=p[VV])


def to_full(x: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rows as filterpy's layout: state (N, 6) (e, n, u, ve, vn, vu) and covariance (N, 6, 6)."""
    n = x.shape[0]
    state = np.concatenate([x[:, :, POS], x[:, :, VEL]], axis=1)
    cov = np.zeros((n, 6, 6))
    for axis in range(3):
        cov[:, axis, axis] = p[:, axis, PP]
        cov[:, axis, axis + 3] = p[:, axis, PV]
        cov[:, axis + 3, axis] = p[:, axis, PV]
        cov[:, axis + 3, axis + 3] = p[:, axis, VV]
    return state, cov
