"""Loss-of-separation detectors: the 4D grid and all-pairs must find exactly the brute-force
oracle's pairs (no missed conflict), with identical figures; symmetry and translation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs_utm.core.monitoring import MonitoringConfig
from gcs_utm.core.monitoring.geometry import window_extents
from gcs_utm.core.monitoring.separation import (
    PredictionError,
    detect_los,
    detect_los_allpairs,
    detect_los_bruteforce,
    detect_los_grid,
)


def _encounters(seed: int, n: int, box_m: float, steps: int, dt_s: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p0 = np.column_stack(
        [rng.uniform(0, box_m, n), rng.uniform(0, box_m, n), rng.uniform(0, 150, n)]
    )
    # Piecewise motion with turns and climbs so boxes and segments are not trivially straight.
    v = rng.uniform(-30, 30, (n, steps - 1, 3)) * np.array([1, 1, 0.2])
    pos = np.concatenate([p0[:, None], p0[:, None] + np.cumsum(v * dt_s, axis=1)], axis=1)
    t = np.arange(steps) * dt_s
    return np.concatenate([pos, np.broadcast_to(t[None, :, None], (n, steps, 1))], axis=2)


def _key(losses: list) -> dict:  # type: ignore[type-arg]
    """Every figure, compared exactly (the grid must give the oracle's floats)."""
    return {
        (x.a, x.b): (
            x.first_loss_t_s,
            x.closest_t_s,
            x.min_distance_m,
            x.min_horizontal_m,
            x.min_vertical_m,
        )
        for x in losses
    }


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    n=st.integers(2, 60),
    box=st.sampled_from([200.0, 800.0, 3000.0]),
    steps=st.integers(1, 25),
    dt=st.sampled_from([0.5, 1.0, 3.0]),
    sphere=st.booleans(),
    dx=st.sampled_from([1.0, 40.0, 400.0]),
    gdt=st.sampled_from([0.0, 1.0, 7.0, 100.0]),
)
def test_grid_and_allpairs_match_bruteforce(
    seed: int, n: int, box: float, steps: int, dt: float, sphere: bool, dx: float, gdt: float
) -> None:
    pts = _encounters(seed, n, box, steps, dt)
    ov = np.random.default_rng(seed + 1).uniform(0, 40, n)
    cfg = MonitoringConfig(
        separation_mode="sphere" if sphere else "cylinder",
        grid_dx_m=dx,
        grid_dy_m=dx,
        grid_dz_m=max(1.0, dx / 4),
        grid_dt_s=gdt,
    )
    oracle = _key(detect_los_bruteforce(pts, ov, cfg))
    assert _key(detect_los_grid(pts, ov, cfg)) == oracle
    assert _key(detect_los_allpairs(pts, ov, cfg)) == oracle
    if steps >= 2:  # window bounds shared with the geofence check (any length) change nothing
        shared = window_extents(pts, 3)
        assert _key(detect_los_grid(pts, ov, cfg, shared)) == oracle


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31), shift=st.tuples(*[st.floats(-5e4, 5e4)] * 3))
def test_symmetry_and_translation_invariance(seed: int, shift: tuple[float, float, float]) -> None:
    pts = _encounters(seed, 30, 500.0, 12, 1.0)
    ov = np.full(30, 10.0)
    cfg = MonitoringConfig()
    base = detect_los_grid(pts, ov, cfg)
    rev = detect_los_grid(pts[::-1].copy(), ov, cfg)
    assert {(29 - x.b, 29 - x.a) for x in rev} == {(x.a, x.b) for x in base}
    moved = pts.copy()
    moved[:, :, :3] += np.array(shift)
    got = {(x.a, x.b): x for x in detect_los_grid(moved, ov, cfg)}
    # Translation can only move pairs sitting exactly on a minimum by rounding; compare
    # the pairs that are clearly inside.
    for x in base:
        if x.min_distance_m < 40.0:
            assert (x.a, x.b) in got
            assert got[(x.a, x.b)].min_distance_m == pytest.approx(x.min_distance_m, abs=1e-6)


def test_fast_crossing_between_samples_is_found() -> None:
    # Two UAS crossing at right angles at 30 m/s, sampled every 10 s: at the samples they are
    # 300 m apart, but they pass through the same point at t = 5 s.
    t = np.array([0.0, 10.0])
    a = np.column_stack([[-150, 150], [0, 0], [100, 100], t])
    b = np.column_stack([[0, 0], [-150, 150], [100, 100], t])
    (x,) = detect_los_grid(np.stack([a, b]), np.zeros(2), MonitoringConfig())
    assert x.closest_t_s == pytest.approx(5.0)
    assert x.min_distance_m == pytest.approx(0.0, abs=1e-9)
    # First loss: 50 m horizontal at closing speed 30*sqrt(2) m/s -> 5 - 50/42.43 s.
    assert x.first_loss_t_s == pytest.approx(5.0 - 50.0 / (30 * np.sqrt(2)), abs=1e-6)


def test_degenerate_inputs() -> None:
    cfg = MonitoringConfig()
    empty = np.empty((0, 5, 4))
    assert detect_los(empty, np.empty(0), cfg) == []
    one = np.zeros((1, 5, 4))
    assert detect_los_grid(one, np.zeros(1), cfg) == []
    same = np.zeros((3, 1, 4))  # identical positions, a single sample
    assert len(detect_los_grid(same, np.zeros(3), cfg)) == 3
    assert len(detect_los_bruteforce(same, np.zeros(3), cfg)) == 3


def test_rows_on_different_time_bases_are_rejected() -> None:
    pts = np.zeros((2, 3, 4))
    pts[0, :, 3] = [0, 1, 2]
    pts[1, :, 3] = [5, 6, 7]
    with pytest.raises(PredictionError):
        detect_los_grid(pts, np.zeros(2), MonitoringConfig())


def test_grid_over_a_huge_spread_with_tiny_cells_matches_oracle() -> None:
    # Keys too wide to pack with the row index: the grid falls back to sorting pairs.
    base = _encounters(3, 20, 300.0, 8, 1.0)
    far = base.copy()
    far[:, :, :2] += 5e8  # m, a second cluster far away
    pts = np.concatenate([base, far])
    ov = np.full(len(pts), 10.0)
    cfg = MonitoringConfig(grid_dx_m=1.0, grid_dy_m=1.0, grid_dz_m=1.0, grid_dt_s=1.0)
    oracle = _key(detect_los_bruteforce(pts, ov, cfg))
    assert len(oracle) >= 2
    assert _key(detect_los_grid(pts, ov, cfg)) == oracle


def test_closest_approach_outside_the_windows_in_loss_is_reported() -> None:
    # B passes 20 m straight over A at t = 5 s (vertical 20 m >= 15 m: no loss there, and
    # their grown boxes do not even overlap in that window), then loses separation at
    # t = 40 s (45 m horizontal, 10 m vertical). The closest approach (20 m at 5 s) lies in
    # a window without loss: the grid must still report it, as the oracle does.
    t = np.arange(61.0)
    a = np.column_stack([np.zeros(61), np.zeros(61), np.full(61, 100.0), t])
    knots_t = [0.0, 10.0, 20.0, 40.0, 60.0]
    b = np.column_stack(
        [
            np.interp(t, knots_t, [-50.0, 50.0, 200.0, 0.0, -200.0]),
            np.interp(t, knots_t, [0.0, 0.0, 0.0, 45.0, 45.0]),
            np.interp(t, knots_t, [120.0, 120.0, 110.0, 110.0, 110.0]),
            t,
        ]
    )
    pts = np.stack([a, b])
    cfg = MonitoringConfig()
    (x,) = detect_los_grid(pts, np.zeros(2), cfg)
    assert _key([x]) == _key(detect_los_bruteforce(pts, np.zeros(2), cfg))
    assert x.closest_t_s == pytest.approx(5.0)
    assert x.min_distance_m == pytest.approx(20.0)
    assert x.min_horizontal_m == pytest.approx(0.0, abs=1e-9)
    assert x.min_vertical_m == pytest.approx(10.0)
    assert 30.0 < x.first_loss_t_s < 40.0


def test_loss_in_the_short_last_window_of_the_last_row() -> None:
    """The last window is shorter than the others (7 segments, windows of 3) and the loss
    is only in its one segment, on the prediction's last row: the windowed detectors gather
    that window past the end of the data and must mask it, giving the oracle's figures."""
    t = np.arange(8.0)
    a = np.column_stack([np.zeros(8), np.zeros(8), np.full(8, 100.0), t])
    b = a.copy()
    b[:, 0] = 500.0
    b[7, 0] = 10.0  # closes in only during the last segment
    c = a.copy()
    c[:, 0] = -3000.0
    pts = np.stack([c, a, b])
    cfg = MonitoringConfig(grid_dt_s=3.0)
    oracle = _key(detect_los_bruteforce(pts, np.zeros(3), cfg))
    assert list(oracle) == [(1, 2)]
    assert oracle[(1, 2)][0] > 6.0  # first loss within the last segment
    assert _key(detect_los_grid(pts, np.zeros(3), cfg)) == oracle
    assert _key(detect_los_allpairs(pts, np.zeros(3), cfg)) == oracle
