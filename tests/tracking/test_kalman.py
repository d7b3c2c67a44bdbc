"""The batched closed-form filter (:func:`kalman.step`, the tracker's one Python step) equals
filterpy's 6-state KalmanFilter (to 1e-9) and keeps its covariance symmetric positive
semi-definite."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs_utm.core.tracking import kalman


def _reference(x0: np.ndarray, p0: np.ndarray) -> KalmanFilter:
    kf = KalmanFilter(dim_x=6, dim_z=3)
    kf.x = x0.copy()
    kf.P = p0.copy()
    return kf


def _ref_step(
    kf: KalmanFilter,
    dt: float,
    q: np.ndarray,
    z: np.ndarray,
    r: np.ndarray,
    zv: np.ndarray | None,
    rv: np.ndarray | None,
) -> None:
    f = np.eye(6)
    f[0:3, 3:6] = np.eye(3) * dt
    unit = Q_discrete_white_noise(dim=2, dt=dt, var=1.0, block_size=3, order_by_dim=False)
    scale = np.sqrt(np.concatenate([q, q]))
    kf.predict(F=f, Q=unit * np.outer(scale, scale))
    if zv is None:
        h = np.hstack([np.eye(3), np.zeros((3, 3))])
        kf.update(z, R=np.diag(r), H=h)
    else:
        assert rv is not None
        kf.update(np.concatenate([z, zv]), R=np.diag(np.concatenate([r, rv])), H=np.eye(6))


def _step_rows(
    x: np.ndarray,
    p: np.ndarray,
    dt: np.ndarray,
    q: np.ndarray,
    z: np.ndarray,
    r: np.ndarray,
    zv: np.ndarray | None = None,
    rv: np.ndarray | None = None,
) -> None:
    """kalman.step on rows (x (N, 3, 2), p (N, 3, 3)), in place: the rows gathered into planes
    as the tracker does, stepped, written back."""
    planes_x = np.ascontiguousarray(x.transpose(2, 1, 0))
    planes_p = np.ascontiguousarray(p.transpose(2, 1, 0))
    if zv is None:
        kalman.step(planes_x, planes_p, dt, q[:, None], z.T.copy(), r.T.copy())
    else:
        assert rv is not None
        kalman.step(
            planes_x, planes_p, dt, q[:, None], z.T.copy(), r.T.copy(), zv.T.copy(), rv.T.copy()
        )
    x[...] = planes_x.transpose(2, 1, 0)
    p[...] = planes_p.transpose(2, 1, 0)


def _predicted_cov_max(p_row: np.ndarray, dt: float, q: np.ndarray) -> float:
    """Largest entry of the prior covariance that the update subtracts from (one row, after
    predicting by ``dt``)."""
    a, b, c = p_row[:, kalman.PP], p_row[:, kalman.PV], p_row[:, kalman.VV]
    dt2 = dt * dt
    prior = [a + 2 * dt * b + dt2 * c + q * dt2 * dt2 / 4, b + dt * c + q * dt2 * dt / 2]
    prior.append(c + q * dt2)
    return float(np.abs(np.array(prior)).max())


step = st.tuples(
    st.floats(0.0, 5.0),  # dt
    st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3),  # z
    st.lists(st.floats(0.01, 100.0), min_size=3, max_size=3),  # sigma
    st.booleans(),  # with velocity
    st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3),  # zv
)


@settings(max_examples=60, deadline=None)
@given(
    steps=st.lists(step, min_size=1, max_size=25),
    q_sigma=st.tuples(st.floats(0.01, 10.0), st.floats(0.01, 10.0)),
)
def test_batched_filter_equals_filterpy(
    steps: list[tuple[float, list[float], list[float], bool, list[float]]],
    q_sigma: tuple[float, float],
) -> None:
    q = np.array([q_sigma[0] ** 2, q_sigma[0] ** 2, q_sigma[1] ** 2])
    x = np.zeros((1, 3, 2))
    x[0, :, 0] = [10.0, -20.0, 100.0]
    p = np.zeros((1, 3, 3))
    p[0, :, kalman.PP] = [4.0, 4.0, 9.0]
    p[0, :, kalman.VV] = 100.0
    x_full, p_full = kalman.to_full(x, p)
    kf = _reference(x_full[0], p_full[0])
    scale = 1.0
    for dt, z_l, sig_l, with_vel, zv_l in steps:
        z = np.array(z_l)
        r = np.array(sig_l) ** 2
        zv = np.array(zv_l)
        rv = r / 10.0
        # Rounding differences scale with the operands: inputs (positions, velocities,
        # sigmas) and the prior covariance the update subtracts from (a large prior and a tiny
        # measurement sigma cancel almost completely): 1e-9 relative to the largest magnitude.
        scale = max(scale, float(np.abs(z).max()), float(np.abs(zv).max()), *sig_l)
        scale = max(scale, _predicted_cov_max(p[0], dt, q))
        if with_vel:
            _step_rows(x, p, np.array([dt]), q, z[None], r[None], zv[None], rv[None])
            _ref_step(kf, dt, q, z, r, zv, rv)
        else:
            _step_rows(x, p, np.array([dt]), q, z[None], r[None])
            _ref_step(kf, dt, q, z, r, None, None)
        state, cov = kalman.to_full(x, p)
        np.testing.assert_allclose(state[0], kf.x, rtol=1e-9, atol=1e-9 * scale)
        np.testing.assert_allclose(cov[0], kf.P, rtol=1e-9, atol=1e-9 * scale)
        # Symmetric by construction; positive semi-definite up to rounding.
        assert np.array_equal(cov[0], cov[0].T)
        assert np.linalg.eigvalsh(cov[0]).min() >= -1e-9 * max(1.0, np.abs(cov[0]).max())


def test_rows_are_independent() -> None:
    """A batch update of many rows equals updating each row alone (no cross-talk)."""
    rng = np.random.default_rng(7)
    n = 50
    x = rng.normal(size=(n, 3, 2)) * 100
    p = np.zeros((n, 3, 3))
    p[:, :, kalman.PP] = rng.uniform(1, 10, size=(n, 3))
    p[:, :, kalman.VV] = rng.uniform(1, 10, size=(n, 3))
    dt = rng.uniform(0, 3, size=n)
    q = np.array([4.0, 4.0, 1.0])
    z = rng.normal(size=(n, 3)) * 100
    r = rng.uniform(1, 20, size=(n, 3))
    xb, pb = x.copy(), p.copy()
    _step_rows(xb, pb, dt, q, z, r)
    for i in range(n):
        xi, pi = x[i : i + 1].copy(), p[i : i + 1].copy()
        _step_rows(xi, pi, dt[i : i + 1], q, z[i : i + 1], r[i : i + 1])
        np.testing.assert_allclose(xb[i], xi[0], rtol=1e-12)
        np.testing.assert_allclose(pb[i], pi[0], rtol=1e-12)


def test_as_accurate_as_filterpy_against_exact_arithmetic() -> None:
    """Against exact rational arithmetic (east axis), on random sequences that include
    ill-conditioned ones (a long prediction, then a precise position + velocity), the
    closed form's error stays within an order of magnitude of filterpy's own (both are
    limited by the conditioning: ~1e-7 relative at worst here). The textbook covariance
    update P - K P of the joint position + velocity update was 125x worse than filterpy
    here, and 3 % of the state on other seeds (now P' = K R: no subtraction)."""
    rng = np.random.default_rng(1)
    worst_ours = worst_ref = 0.0
    for _ in range(130):
        qs = float(rng.choice([0.01, 0.125, 1.0, 5.0, 10.0]))
        q = np.full(3, qs**2)
        x = np.zeros((1, 3, 2))
        x[0, :, 0] = [10.0, -20.0, 100.0]
        p = np.zeros((1, 3, 3))
        p[0, :, kalman.PP] = [4.0, 4.0, 9.0]
        p[0, :, kalman.VV] = 100.0
        x_full, p_full = kalman.to_full(x, p)
        kf = _reference(x_full[0], p_full[0])
        ex = [Fraction(10), Fraction(0)]
        a, b, c = Fraction(4), Fraction(0), Fraction(100)
        q_f = Fraction(qs) ** 2
        for _ in range(int(rng.integers(1, 26))):
            dt = float(rng.choice([0.0, 0.0, rng.uniform(0, 5), 3.0, 5.0]))
            z = rng.choice([0.0, 1.0], size=3) * rng.uniform(-1e4, 1e4, size=3)
            r = rng.choice([0.01, 0.125, 1.0, 45.0, rng.uniform(0.01, 100)], size=3) ** 2
            with_vel = bool(rng.random() < 0.3)
            zv = rng.uniform(-50, 50, size=3) * rng.choice([0.0, 1.0])
            rv = r / 10
            if with_vel:
                _step_rows(x, p, np.array([dt]), q, z[None], r[None], zv[None], rv[None])
                _ref_step(kf, dt, q, z, r, zv, rv)
            else:
                _step_rows(x, p, np.array([dt]), q, z[None], r[None])
                _ref_step(kf, dt, q, z, r, None, None)
            # The same step exactly, east axis only (the axes are independent).
            d = Fraction(dt)
            a, b, c = (
                a + 2 * d * b + d * d * c + q_f * d**4 / 4,
                b + d * c + q_f * d**3 / 2,
                c + q_f * d * d,
            )
            ex = [ex[0] + ex[1] * d, ex[1]]
            r_f = Fraction(float(r[0]))
            y1 = Fraction(float(z[0])) - ex[0]
            if with_vel:
                rv_f = Fraction(float(rv[0]))
                s11, s22 = a + r_f, c + rv_f
                det = s11 * s22 - b * b
                k11, k12 = (a * s22 - b * b) / det, (b * s11 - a * b) / det
                k21, k22 = (b * s22 - c * b) / det, (c * s11 - b * b) / det
                y2 = Fraction(float(zv[0])) - ex[1]
                ex = [ex[0] + k11 * y1 + k12 * y2, ex[1] + k21 * y1 + k22 * y2]
                a, b, c = k11 * r_f, k12 * rv_f, k22 * rv_f
            else:
                s = a + r_f
                ex = [ex[0] + a / s * y1, ex[1] + b / s * y1]
                a, b, c = a * r_f / s, b * r_f / s, c - b * b / s
            want = np.array([float(ex[0]), float(ex[1])])
            norm = max(1.0, float(np.abs(want).max()))
            worst_ours = max(worst_ours, float(np.abs(x[0, 0] - want).max()) / norm)
            worst_ref = max(worst_ref, float(np.abs(kf.x[[0, 3]] - want).max()) / norm)
    assert worst_ours <= max(10.0 * worst_ref, 1e-12), (worst_ours, worst_ref)


@settings(max_examples=40, deadline=None)
@given(m=st.integers(1, 12), with_vel=st.booleans(), seed=st.integers(0, 99))
def test_positions_predicted_by_the_caller_give_the_same_step_bit_for_bit(
    m: int, with_vel: bool, seed: int
) -> None:
    """The tracker moves positions by vel * dt itself to gate, then steps with
    ``positions_predicted``: the result must be the plain step's, exactly."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(2, 3, m)) * 100
    p = np.zeros((3, 3, m))
    p[kalman.PP] = rng.uniform(0.1, 50, size=(3, m))
    p[kalman.PV] = rng.uniform(-1, 1, size=(3, m))
    p[kalman.VV] = rng.uniform(0.1, 50, size=(3, m))
    dt = rng.uniform(0, 5, size=m)
    q = np.array([[4.0], [4.0], [1.0]])
    z = rng.normal(size=(3, m)) * 100
    r = rng.uniform(0.01, 20, size=(3, m))
    zv = rng.normal(size=(3, m)) * 10 if with_vel else None
    rv = np.repeat(rng.uniform(0.01, 5, size=(1, m)), 3, axis=0) if with_vel else None
    plain_x, plain_p = x.copy(), p.copy()
    kalman.step(plain_x, plain_p, dt, q, z, r, zv, rv)
    moved_x, moved_p = x.copy(), p.copy()
    moved_x[kalman.POS] += moved_x[kalman.VEL] * dt
    kalman.step(moved_x, moved_p, dt, q, z, r, zv, rv, positions_predicted=True)
    assert np.array_equal(plain_x, moved_x)
    assert np.array_equal(plain_p, moved_p)


@settings(max_examples=60, deadline=None)
@given(
    pp=st.floats(0.01, 1e4),
    vv=st.floats(0.01, 1e3),
    corr=st.floats(-0.99, 0.99),
    q_var=st.floats(0.0, 100.0),
    tau_s=st.floats(0.0, 120.0),
)
def test_the_one_propagation_equals_filterpy_predict(
    pp: float, vv: float, corr: float, q_var: float, tau_s: float
) -> None:
    """kalman.propagated_pp (step's predict, the snapshot's variances, the prediction's
    radius) is filterpy's predicted position variance after ``tau_s`` without updates."""
    pv = corr * np.sqrt(pp * vv)
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.P = np.array([[pp, pv], [pv, vv]])
    f = np.array([[1.0, tau_s], [0.0, 1.0]])
    kf.predict(F=f, Q=Q_discrete_white_noise(dim=2, dt=tau_s, var=q_var))
    got = kalman.propagated_pp(
        np.array([pp]), np.array([pv]), np.array([vv]), q_var, np.array([tau_s])
    )
    np.testing.assert_allclose(got[0], kf.P[0, 0], rtol=1e-9, atol=1e-9 * max(1.0, pp))


def test_prediction_radius_is_the_propagated_variance_of_every_axis() -> None:
    """The prediction's radius (prediction.extrapolate) is the root of the summed position
    variances the snapshot propagates per axis (kalman.predicted_position_var)."""
    from gcs_utm.core.tracking.prediction import extrapolate

    rng = np.random.default_rng(3)
    n, k = 5, 7
    x = rng.normal(size=(n, 3, 2))
    p = np.zeros((n, 3, 3))
    p[:, :, kalman.PP] = rng.uniform(1.0, 50.0, (n, 3))
    p[:, :, kalman.VV] = rng.uniform(0.1, 5.0, (n, 3))
    p[:, :, kalman.PV] = 0.5 * np.sqrt(p[:, :, kalman.PP] * p[:, :, kalman.VV])
    q = np.array([0.5, 0.5, 0.2])
    ahead0 = rng.uniform(0.0, 2.0, n)
    steps = np.arange(k) * 1.0
    _, radius = extrapolate(x, p, q, ahead0, steps)
    per_axis = kalman.predicted_position_var(p, np.add.outer(ahead0, steps), q)
    np.testing.assert_allclose(radius**2, per_axis.sum(axis=2), rtol=1e-12)
