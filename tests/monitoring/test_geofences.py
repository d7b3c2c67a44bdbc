"""4D geofence check: the prefiltered, batched ``check_geofences`` finds exactly the hits of
the per-fence, every-segment oracle; band and activation edges; holes; degenerate input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

from gcs_utm.core.monitoring.checks import FenceHit, check_geofences, check_geofences_bruteforce
from gcs_utm.core.monitoring.fences import LocalFence
from gcs_utm.core.monitoring.geometry import FloatArray, ring_edges, window_extents
from gcs_utm.model import GeofenceId


def _poly_fence(
    gid: str,
    rings: list[FloatArray],
    z: tuple[float, float] = (0.0, 200.0),
    t: tuple[float, float] = (-math.inf, math.inf),
) -> LocalFence:
    """A polygon fence from rings (exterior first, then holes), oriented for the winding
    test (holes opposite to the exterior)."""
    poly = orient(Polygon(rings[0], rings[1:]), 1.0)
    rr = [np.asarray(poly.exterior.coords)[:-1]] + [
        np.asarray(i.coords)[:-1] for i in poly.interiors
    ]
    edges = np.concatenate([ring_edges(r[:, 0], r[:, 1]) for r in rr])
    return LocalFence(
        id=GeofenceId(gid),
        edges=edges,
        center=None,
        radius_m=0.0,
        z_lo=z[0],
        z_hi=z[1],
        t_lo=t[0],
        t_hi=t[1],
        bbox=(edges[:, 0].min(), edges[:, 1].min(), edges[:, 0].max(), edges[:, 1].max()),
    )


def _cyl_fence(
    gid: str,
    c: tuple[float, float],
    r: float,
    z: tuple[float, float] = (0.0, 200.0),
    t: tuple[float, float] = (-math.inf, math.inf),
) -> LocalFence:
    return LocalFence(
        id=GeofenceId(gid),
        edges=None,
        center=c,
        radius_m=r,
        z_lo=z[0],
        z_hi=z[1],
        t_lo=t[0],
        t_hi=t[1],
        bbox=(c[0] - r, c[1] - r, c[0] + r, c[1] + r),
    )


STAR = np.array(
    [
        (math.cos(a) * (100 if i % 2 == 0 else 35), math.sin(a) * (100 if i % 2 == 0 else 35))
        for i, a in enumerate(np.linspace(0, 2 * np.pi, 10, endpoint=False))
    ]
)
U = np.array(
    [(0, 0), (300, 0), (300, 300), (200, 300), (200, 100), (100, 100), (100, 300), (0, 300)]
)
SQUARE = np.array([(-100, -100), (100, -100), (100, 100), (-100, 100)], float)
HOLE = np.array([(-40, -40), (40, -40), (40, 40), (-40, 40)], float)


def _key(hits: list[FenceHit]) -> list[tuple[int, str, bool, float]]:
    return sorted((h.row, str(h.geofence_id), h.inside_now, h.entry_t_s) for h in hits)


def _traffic(seed: int, n: int, steps: int, box: float, dt: float) -> FloatArray:
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(-box, box, (n, 2)), rng.uniform(0, 200, n)])
    v = rng.uniform(-40, 40, (n, max(steps - 1, 0), 3)) * np.array([1, 1, 0.3])
    still = rng.random(n) < 0.1  # hovering UAS: zero-length segments
    v[still] = 0.0
    pos = np.concatenate([p0[:, None], p0[:, None] + np.cumsum(v * dt, axis=1)], axis=1)
    t = 1000.0 + np.arange(steps) * dt
    return np.concatenate([pos, np.broadcast_to(t[None, :, None], (n, steps, 1))], axis=2)


def _fences(seed: int, box: float) -> list[LocalFence]:
    rng = np.random.default_rng(seed)
    out: list[LocalFence] = []
    for i in range(int(rng.integers(1, 12))):
        c = rng.uniform(-box, box, 2)
        zlo = float(rng.choice([0.0, rng.uniform(0, 150)]))
        z = (zlo, zlo + float(rng.uniform(1, 100)))
        # Unbounded, or activating / expiring somewhere in the horizon.
        t = (
            float(rng.choice([-math.inf, 1000.0 + rng.uniform(0, 40)])),
            float(rng.choice([math.inf, 1000.0 + rng.uniform(20, 80)])),
        )
        kind = i % 5
        if kind == 0:
            out.append(_cyl_fence(f"c{i}", (c[0], c[1]), float(rng.uniform(5, 300)), z, t))
        elif kind == 1:
            out.append(_poly_fence(f"s{i}", [STAR * rng.uniform(0.5, 3) + c], z, t))
        elif kind == 2:
            out.append(_poly_fence(f"u{i}", [U + c], z, t))
        elif kind == 3:  # thin wall, 0.5-3 m wide: crossed between samples
            w = float(rng.uniform(0.5, 3))
            wall = np.array([(0, -300), (w, -300), (w, 300), (0, 300)]) + c
            out.append(_poly_fence(f"w{i}", [wall], z, t))
        else:  # square with a hole
            out.append(_poly_fence(f"h{i}", [SQUARE * 2 + c, HOLE * 2 + c], z, t))
    return out


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    n=st.integers(1, 40),
    steps=st.integers(1, 30),
    box=st.sampled_from([150.0, 600.0, 3000.0]),
    dt=st.sampled_from([0.5, 1.0, 4.0]),
    w=st.sampled_from([1, 3, 10, 100]),
)
def test_prefiltered_check_matches_every_segment_oracle(
    seed: int, n: int, steps: int, box: float, dt: float, w: int
) -> None:
    pts = _traffic(seed, n, steps, box, dt)
    fences = _fences(seed + 1, box)
    want = _key(check_geofences_bruteforce(pts, fences))
    assert _key(check_geofences(pts, fences)) == want
    if steps >= 2:
        assert _key(check_geofences(pts, fences, window_extents(pts, w))) == want


def _line(
    p: tuple[float, float, float], v: tuple[float, float, float], steps: int = 61
) -> FloatArray:
    k = np.arange(steps, dtype=float)
    row = np.empty((1, steps, 4))
    row[0, :, :3] = np.array(p) + np.outer(k, v)
    row[0, :, 3] = k
    return row


def test_altitude_band_edges_just_above_and_below() -> None:
    level = _line((0, 0, 100), (10, 0, 0))  # level at 100 m through the fence centre
    for z, hit in (
        ((100.001, 200), False),  # band starts just above
        ((0, 99.999), False),  # band ends just below
        ((100, 200), True),  # band floor exactly at the UAS: closed band, inside
        ((0, 100), True),
    ):
        got = check_geofences(level, [_cyl_fence("c", (0, 0), 50, z)])
        assert bool(got) is hit, z
    # Climbing 1 m/s from 90 m into a band starting at 100.5 m: entry at t = 10.5 s.
    climb = _line((0, 0, 90), (0, 0, 1))
    (h,) = check_geofences(climb, [_cyl_fence("c", (0, 0), 50, (100.5, 200))])
    assert not h.inside_now and h.entry_t_s == pytest.approx(10.5)


def test_fence_activating_mid_horizon() -> None:
    row = _line((0, 0, 100), (10, 0, 0))  # at x = 10 t
    ahead = _cyl_fence("late", (300, 0), 100, t=(25.0, math.inf))  # reached at 20 s
    (h,) = check_geofences(row, [ahead])
    assert h.entry_t_s == pytest.approx(25.0) and not h.inside_now  # inside when it starts
    later = _cyl_fence("later", (300, 0), 100, t=(45.0, math.inf))  # UAS gone at 40 s
    assert check_geofences(row, [later]) == []
    expired = _cyl_fence("old", (300, 0), 100, t=(-math.inf, 15.0))
    assert check_geofences(row, [expired]) == []
    inverted = _cyl_fence("bad", (300, 0), 100, t=(50.0, 10.0))  # empty window: never active
    assert check_geofences(row, [inverted]) == check_geofences_bruteforce(row, [inverted]) == []
    # Already inside when the fence activates at the first sample: an intrusion.
    here = _cyl_fence("here", (0, 0), 100, t=(0.0, 1.0))
    (h2,) = check_geofences(row, [here])
    assert h2.inside_now and h2.entry_t_s == 0.0


def test_holes_and_thin_walls() -> None:
    holed = _poly_fence("h", [SQUARE * 2, HOLE * 2])  # hole |x|, |y| < 80
    hover_in_hole = _line((0, 0, 100), (0, 0, 0))
    assert check_geofences(hover_in_hole, [holed]) == []
    (h,) = check_geofences(_line((0, 0, 100), (5, 0, 0)), [holed])  # leaves the hole east
    assert h.entry_t_s == pytest.approx(16.0)
    wall = _poly_fence("w", [np.array([(299.0, -500), (300.0, -500), (300.0, 500), (299, 500)])])
    # 40 m per sample from x = 5: samples at 285 and 325, none inside the 1 m wall.
    (hw,) = check_geofences(_line((5, 0, 100), (40, 0, 0)), [wall])
    assert hw.entry_t_s == pytest.approx((299 - 5) / 40)


def test_degenerate_input() -> None:
    f = [_cyl_fence("c", (0, 0), 50), _poly_fence("s", [STAR])]
    assert check_geofences(np.empty((0, 61, 4)), f) == []
    assert check_geofences(_line((0, 0, 100), (1, 0, 0)), []) == []
    one_sample = _line((0, 0, 100), (0, 0, 0), steps=1)
    assert {h.geofence_id for h in check_geofences(one_sample, f)} == {"c", "s"}
    same = np.repeat(_line((0, 0, 100), (0, 0, 0)), 3, axis=0)  # identical hovering UAS
    assert len(check_geofences(same, f)) == 6


def test_entry_late_in_a_long_stay_inside_the_fence_box() -> None:
    """Rows inside a fence's bounding box for the whole horizon but outside the polygon until
    segment k (tested in rounds of 1, 2, 4, ... segments): each reports the entry in
    segment k, as the every-segment oracle does; a row that never enters reports none."""
    tri = _poly_fence("t", [np.array([(0.0, 0.0), (1000.0, 0.0), (0.0, 1000.0)])])
    ks = (0, 1, 2, 3, 5, 6, 7, 20, 59)
    # West at 10 m/s along y = 850: inside the triangle once x < 150.
    rows = [_line((150.0 + 10.0 * k + 5.0, 850.0, 100.0), (-10.0, 0.0, 0.0)) for k in ks]
    rows.append(_line((950.0, 950.0, 100.0), (0.0, 0.0, 0.0)))  # in the box, never in
    pts = np.concatenate(rows)
    hits = check_geofences(pts, [tri])
    assert _key(hits) == _key(check_geofences_bruteforce(pts, [tri]))
    assert [h.row for h in hits] == list(range(len(ks)))
    for h, k in zip(hits, ks, strict=True):
        assert h.entry_t_s == pytest.approx(k + 0.5)
