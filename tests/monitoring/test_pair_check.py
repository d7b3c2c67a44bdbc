"""The batched exact check (``pair_check.check_pairs``: a coarse screen, windows of samples
around each minimum) gives bit for bit the figures of checking every sample of every pair
one pair at a time (``strategic_oracle.pair_conflict``), on random pairs built to be hard for
the windows: long spans (hundreds of samples), level flight (equal vertical distance on every
sample), level legs at two heights, climbs, crossings, parallel tracks (every sample near the
minimum), separations on the minima exactly, repeated waypoint times and single-waypoint
plans."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from strategic_oracle import pair_conflict

from gcs_utm.core.monitoring.pair_check import check_pairs
from gcs_utm.model import OperationId

T0 = 1.7e9  # s


def _plan(rng: np.random.Generator, box_m: float) -> np.ndarray:
    k = int(rng.integers(1, 7)) if rng.random() < 0.2 else int(rng.integers(2, 7))
    legs = rng.choice([0.0, 20.0, 45.5, 120.0, 300.0], k - 1) if rng.random() < 0.3 else None
    dt = legs if legs is not None else rng.uniform(20.0, 300.0, k - 1)
    t = T0 + float(rng.uniform(0, 60)) + np.concatenate([[0.0], np.cumsum(dt)])
    xy = rng.uniform(-box_m, box_m, (k, 2))
    z = rng.choice([100.0, 108.0, 115.0, 140.0], k)
    if rng.random() < 0.4:  # level flight
        z[:] = z[0]
    elif rng.random() < 0.5:  # level legs at two heights, a climb between
        z[: k // 2] = z[0]
        z[k // 2 :] = z[-1]
    return np.column_stack([xy, z, t])


def _pairs(seed: int, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        box_m = float(rng.choice([60.0, 300.0, 2000.0]))
        a = _plan(rng, box_m)
        b = _plan(rng, box_m)
        if rng.random() < 0.15:  # parallel: the same track, shifted sideways and up
            b = a + np.array([float(rng.choice([0.0, 30.0, 50.0])), 0.0, 15.0, 0.0])
        out.append((a, b))
    return out


def _figures(c: object) -> tuple[float, ...] | None:
    if c is None:
        return None
    return tuple(
        getattr(c, f)
        for f in (
            "first_loss_t_s",
            "closest_t_s",
            "min_distance_m",
            "min_horizontal_m",
            "min_vertical_m",
        )
    )


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize(
    ("spherical", "min_h", "min_v", "step_s"),
    [
        (False, 50.0, 15.0, 1.0),
        (False, 50.0, 15.0, 0.3),
        (False, 120.0, 30.0, 7.0),
        (True, 60.0, 60.0, 2.5),
        (False, 50.0, 15.0, 0.0),
    ],
)
def test_batched_check_equals_every_sample_pair_by_pair(
    seed: int, spherical: bool, min_h: float, min_v: float, step_s: float
) -> None:
    pairs = _pairs(seed, 120)
    local = [p for pair in pairs for p in pair]
    ia = np.arange(0, len(local), 2)
    ib = ia + 1
    mh = np.full(len(pairs), min_h)
    mv = np.full(len(pairs), min_v)
    got = check_pairs(local, ia, ib, mh, mv, spherical=spherical, step_s=step_s)
    conflicts = 0
    for k, (a, b) in enumerate(pairs):
        ref = pair_conflict(
            a,
            b,
            ida=OperationId("a"),
            idb=OperationId("b"),
            min_h=min_h,
            min_v=min_v,
            spherical=spherical,
            step_s=step_s,
        )
        mine = None
        if got.conflict[k]:
            mine = (
                float(got.first_loss_t_s[k]),
                float(got.closest_t_s[k]),
                float(got.min_distance_m[k]),
                float(got.min_horizontal_m[k]),
                float(got.min_vertical_m[k]),
            )
        assert mine == _figures(ref), f"pair {k}: {a.tolist()} / {b.tolist()}"
        conflicts += ref is not None
    assert conflicts >= 10  # the airspace is dense enough to test the figures
