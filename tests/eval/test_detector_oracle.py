"""The loss-of-separation detector against an independent oracle written here: for every pair
of predicted trajectories and every segment, the relative motion is linear, so the instants
in loss are where a quadratic (horizontal, or 3D for the sphere rule) and a linear inequality
(vertical) hold; a pair loses separation iff some segment's two intervals overlap. Plain
Python floats, no NumPy and nothing of the production code but the function under test.

Agreement is required on every pair whose margin exceeds 1 mm: the oracle decides the pair
with both minima 1 mm smaller and 1 mm larger; when the two answers agree, the detector
(all-pairs and 4D-grid paths) must give the same answer."""

from __future__ import annotations

import math
import random
from collections.abc import Callable

import numpy as np
import pytest

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.separation import detect_los

MARGIN_M = 0.001
Minima = tuple[float, float, bool]  # horizontal m, vertical m, sphere rule


def _below_quadratic(a: float, b: float, c: float) -> tuple[float, float] | None:
    """Open interval of u where a u^2 + b u + c < 0 (a >= 0), or None."""
    if a <= 1e-18:
        if abs(b) <= 1e-18:
            return (-math.inf, math.inf) if c < 0.0 else None
        root = -c / b
        return (-math.inf, root) if b > 0.0 else (root, math.inf)
    disc = b * b - 4.0 * a * c
    if disc <= 0.0:
        return None
    s = math.sqrt(disc)
    return ((-b - s) / (2.0 * a), (-b + s) / (2.0 * a))


def _segment_loss(
    r0: tuple[float, float, float],
    dr: tuple[float, float, float],
    min_h_m: float,
    min_v_m: float,
    *,
    sphere: bool,
) -> bool:
    """Does r0 + u dr (u in [0, 1]) come inside the minima?"""
    lo, hi = 0.0, 1.0
    if sphere:
        a = dr[0] ** 2 + dr[1] ** 2 + dr[2] ** 2
        b = 2.0 * (r0[0] * dr[0] + r0[1] * dr[1] + r0[2] * dr[2])
        c = r0[0] ** 2 + r0[1] ** 2 + r0[2] ** 2 - min_h_m**2
        iv = _below_quadratic(a, b, c)
        return iv is not None and max(lo, iv[0]) < min(hi, iv[1])
    a = dr[0] ** 2 + dr[1] ** 2
    b = 2.0 * (r0[0] * dr[0] + r0[1] * dr[1])
    c = r0[0] ** 2 + r0[1] ** 2 - min_h_m**2
    horizontal = _below_quadratic(a, b, c)
    # |z0 + dz u| < V  <=>  (dz u + z0)^2 - V^2 < 0
    vertical = _below_quadratic(dr[2] ** 2, 2.0 * r0[2] * dr[2], r0[2] ** 2 - min_v_m**2)
    if horizontal is None or vertical is None:
        return False
    return max(lo, horizontal[0], vertical[0]) < min(hi, horizontal[1], vertical[1])


def _pair_loss(
    pa: list[tuple[float, float, float]],
    pb: list[tuple[float, float, float]],
    min_h_m: float,
    min_v_m: float,
    *,
    sphere: bool,
) -> bool:
    for k in range(len(pa) - 1):
        r0 = (pa[k][0] - pb[k][0], pa[k][1] - pb[k][1], pa[k][2] - pb[k][2])
        r1 = (pa[k + 1][0] - pb[k + 1][0], pa[k + 1][1] - pb[k + 1][1], pa[k + 1][2] - pb[k + 1][2])
        dr = (r1[0] - r0[0], r1[1] - r0[1], r1[2] - r0[2])
        if _segment_loss(r0, dr, min_h_m, min_v_m, sphere=sphere):
            return True
    return False


def _minima(config: MonitoringConfig, ov_a: float, ov_b: float) -> tuple[float, float]:
    """The effective minima, written out here from the rule (operational volumes add up)."""
    floor = ov_a + ov_b
    if config.separation_mode == "sphere":
        s = max(config.safety_distance_m, floor)
        return s, s
    return max(config.separation_horizontal_m, floor), max(config.separation_vertical_m, floor)


def _trajectories(
    rng: random.Random, n: int, steps: int, dt_s: float, minima: Callable[[int, int], Minima]
) -> np.ndarray:
    """Random walks with turns and climbs. Every third UAS is then placed against an earlier
    one at an offset within centimetres of the pair's minima, on either side: half of them as
    a rigid copy of the other's trajectory (the distance is the offset all along), half as
    their own walk shifted to pass at that offset at one sample."""
    pts = np.zeros((n, steps, 4))
    for i in range(n):
        e, nn, z = rng.uniform(-300, 300), rng.uniform(-300, 300), rng.uniform(650, 800)
        speed, heading, climb = rng.uniform(2, 25), rng.uniform(0, 2 * math.pi), 0.0
        for k in range(steps):
            pts[i, k] = (e, nn, z, 1000.0 + k * dt_s)
            heading += rng.gauss(0.0, 0.15)
            climb = max(-3.0, min(3.0, climb + rng.gauss(0.0, 0.5)))
            e += math.sin(heading) * speed * dt_s
            nn += math.cos(heading) * speed * dt_s
            z += climb * dt_s
    for i in range(2, n, 3):
        j = rng.randrange(i)
        k = rng.randrange(steps)
        min_h, min_v, sphere = minima(i, j)
        delta = rng.choice((-0.02, -0.002, -0.0005, 0.0005, 0.002, 0.02, 0.5, -0.5))
        ang = rng.uniform(0, 2 * math.pi)
        if sphere:
            elev = rng.uniform(-1.2, 1.2)
            r = min_h + delta
            off = (
                r * math.cos(elev) * math.sin(ang),
                r * math.cos(elev) * math.cos(ang),
                r * math.sin(elev),
            )
        elif rng.random() < 0.5:
            h = min_h + delta
            off = (h * math.sin(ang), h * math.cos(ang), rng.uniform(-0.9, 0.9) * min_v)
        else:
            h = rng.uniform(0.0, 0.9) * min_h
            off = (h * math.sin(ang), h * math.cos(ang), rng.choice((-1.0, 1.0)) * (min_v + delta))
        if rng.random() < 0.5:
            pts[i, :, :3] = pts[j, :, :3] + off
        else:
            pts[i, :, :3] += pts[j, k, :3] + off - pts[i, k, :3]
    return pts


@pytest.mark.parametrize("mode", ["cylinder", "sphere"])
@pytest.mark.parametrize("path", ["allpairs", "grid"])
def test_detector_agrees_with_the_oracle_beyond_1_mm(mode: str, path: str) -> None:
    config = MonitoringConfig(
        separation_mode=mode,
        safety_distance_m=30.0,
        allpairs_below=10**9 if path == "allpairs" else 0,
    )
    checked = decided = losses = 0
    sphere = mode == "sphere"
    for seed in range(12):
        rng = random.Random(seed)
        ov = np.array([rng.choice((0.0, 10.0, 15.0, 30.0)) for _ in range(14)])

        def minima(i: int, j: int, ov: np.ndarray = ov) -> Minima:
            return (*_minima(config, ov[i], ov[j]), sphere)

        pts = _trajectories(rng, 14, 25, rng.choice((1.0, 2.0, 5.0)), minima)
        found = {(r.a, r.b) for r in detect_los(pts, ov, config)}
        rows = [[(p[0], p[1], p[2]) for p in traj] for traj in pts.tolist()]
        for a in range(len(pts)):
            for b in range(a + 1, len(pts)):
                min_h, min_v = _minima(config, ov[a], ov[b])
                inner = _pair_loss(
                    rows[a], rows[b], min_h - MARGIN_M, min_v - MARGIN_M, sphere=sphere
                )
                outer = _pair_loss(
                    rows[a], rows[b], min_h + MARGIN_M, min_v + MARGIN_M, sphere=sphere
                )
                checked += 1
                if inner != outer:
                    continue  # within 1 mm of a minimum: either answer is right
                decided += 1
                losses += inner
                assert ((a, b) in found) == inner, (seed, a, b, min_h, min_v, inner)
    # the set exercises both answers and the threshold
    assert losses >= 20 and decided - losses >= 100, (checked, decided, losses)
    assert checked - decided >= 1, "no pair within 1 mm of a minimum: the set is too easy"
