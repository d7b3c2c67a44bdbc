"""``Tracker.snapshot`` (what the monitoring cycle reads) returns exactly what the plain
per-track construction returns: every ``Track`` field equal, same ids in the same order, and
the same prediction as ``Tracker.predict`` at that time. Plus the column-wise ``Track``
builder it uses, against the dataclass constructor."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import FRAME, T0, meas, new_tracker, operation, plan_from_local

from gcs_utm.core.tracking import Tracker, current_waypoint, kalman
from gcs_utm.core.tracking.tracks import build_tracks
from gcs_utm.model import Icao24, MeasurementSource, OperationId, Track, TrackId

FIELDS = [
    "id", "t_s", "lat_deg", "lon_deg", "alt_amsl_m", "east_m", "north_m", "vel_enu_mps",
    "position_sigma_m", "cooperative", "operation_id", "icao24", "stale", "updates",
    "next_waypoint", "measured_t_s",
]  # fmt: skip


def _reference_tracks(tr: Tracker, t_s: float) -> dict[TrackId, Track]:
    """The straightforward construction (the implementation before the column-wise one):
    propagate each row to ``t_s``, convert every field with float()/bool()/int() and call
    ``Track(...)`` per row. The current waypoint comes from an independent full search of
    the track's own plan (:func:`current_waypoint`)."""
    n = len(tr)
    dt = t_s - tr._t[:n]
    x = tr._x[:n]
    pos = x[:, :, kalman.POS] + x[:, :, kalman.VEL] * dt[:, None]
    vel = x[:, :, kalman.VEL]
    pos_var = kalman.predicted_position_var(tr._p[:n], dt[:, None], tr._q)[:, 0, :]
    lat, lon = FRAME.to_wgs84(pos[:, 0], pos[:, 1])
    sigma = np.sqrt(pos_var.sum(axis=1))
    out: dict[TrackId, Track] = {}
    for i in range(n):
        tid = tr._ids[i]
        op = tr.track_operation(tid)
        wp = None
        if op is not None:
            wp = current_waypoint(
                op.plan,
                FRAME,
                east_m=float(pos[i, 0]),
                north_m=float(pos[i, 1]),
                alt_amsl_m=float(pos[i, 2]),
                t_s=float(t_s),
                ambiguity_m=op.flight_geometry_m * tr.config.plan_ambiguity_factor,
            )
        out[tid] = Track(
            id=tid,
            t_s=float(np.full(n, t_s)[i]),
            lat_deg=float(lat[i]),
            lon_deg=float(lon[i]),
            alt_amsl_m=float(pos[i, 2]),
            east_m=float(pos[i, 0]),
            north_m=float(pos[i, 1]),
            vel_enu_mps=(float(vel[i, 0]), float(vel[i, 1]), float(vel[i, 2])),
            position_sigma_m=float(sigma[i]),
            cooperative=bool(tr._coop[i]),
            operation_id=tr._op_ids[i],
            icao24=tr._icao[i],
            stale=bool(tr._stale[i]),
            updates=int(tr._updates[i]),
            next_waypoint=wp,
            measured_t_s=None if tr._t[i] == t_s else float(tr._t[i]),
        )
    return out


def _random_airspace(seed: int, *, intruders: bool = True) -> tuple[Tracker, float]:
    """UAS on random plans (some flying them, some far off, some not seen), ADS-B and
    MAVLink intruders (unless ``intruders`` is False: then every track has a plan),
    velocity measurements, stale tracks."""
    rng = np.random.default_rng(seed)
    tr = new_tracker()
    ops = []
    truth = []
    for j in range(int(rng.integers(3, 12))):
        m = int(rng.integers(2, 12))
        start = rng.uniform(-2_000, 2_000, size=2)
        pts = start + np.cumsum(rng.normal(size=(m, 2)) * 80.0, axis=0)
        alt = float(rng.uniform(60, 120))
        plan_pts = [(float(e), float(n), alt, T0 + 10.0 * k) for k, (e, n) in enumerate(pts)]
        by_icao = j % 2 == 1
        ops.append(
            operation(
                f"op{j}",
                plan_from_local(f"op{j}", plan_pts),
                sys_id=None if by_icao else 10 + j,
                icao24=f"{j:06x}" if by_icao else None,
                flight_geometry_m=float(rng.uniform(5, 30)),
            )
        )
        truth.append((plan_pts, by_icao, j, float(rng.uniform(0, 300)) * (rng.random() < 0.3)))
    tr.set_operations(ops)
    seconds = int(rng.integers(2, 25))
    for s in range(seconds):
        batch = []
        for plan_pts, by_icao, j, off in truth:
            if rng.random() < 0.15:
                continue
            t = T0 + s + float(rng.uniform(0, 0.9))
            e = float(np.interp(t, [p[3] for p in plan_pts], [p[0] for p in plan_pts]))
            n = float(np.interp(t, [p[3] for p in plan_pts], [p[1] for p in plan_pts]))
            vel = tuple(rng.normal(size=3).tolist()) if rng.random() < 0.4 else None
            batch.append(
                meas(
                    e + off + rng.normal(),
                    n + rng.normal(),
                    plan_pts[0][2] + rng.normal(),
                    t,
                    source=MeasurementSource.ADSB if by_icao else MeasurementSource.TELEMETRY,
                    sys_id=None if by_icao else 10 + j,
                    icao24=f"{j:06x}" if by_icao else None,
                    vel_ned_mps=vel,  # type: ignore[arg-type]
                )
            )
        if intruders and s < seconds // 2:  # intruders that go silent half way: stale
            t = T0 + s + 0.5
            batch.append(meas(500.0 + 40 * s, 0, 300, t, source=MeasurementSource.ADSB,
                              sys_id=None, icao24="abcdef"))  # fmt: skip
            batch.append(meas(-500.0, 30 * s, 50, t, sys_id=200))
        tr.ingest(batch)
        tr.check_stale(T0 + s + 1.0)
    return tr, T0 + seconds


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), ahead=st.floats(-3.0, 30.0), intruders=st.booleans())
def test_snapshot_equals_the_plain_per_track_construction(
    seed: int, ahead: float, intruders: bool
) -> None:
    tr, t_end = _random_airspace(seed, intruders=intruders)
    t_s = t_end + ahead
    tracks, pred = tr.snapshot(t_s)
    ref = _reference_tracks(tr, t_s)
    assert list(tracks) == list(ref)
    for tid, track in tracks.items():
        assert track == ref[tid], tid
        assert type(track) is Track
        assert [type(getattr(track, f)) for f in FIELDS] == [
            type(getattr(ref[tid], f)) for f in FIELDS
        ]
    assert pred.track_ids == tuple(tracks)
    again = tr.predict(t_s)
    assert np.array_equal(pred.points, again.points)
    assert np.array_equal(pred.sigma_m, again.sigma_m)


def test_snapshot_covers_every_kind_of_track() -> None:
    """The random airspace really has what the equality test claims to cover."""
    tr, t_end = _random_airspace(3)
    tracks, _ = tr.snapshot(t_end)
    kinds = {(t.cooperative, t.stale, t.next_waypoint is None) for t in tracks.values()}
    assert (False, True, True) in kinds  # stale intruders, no plan
    assert (True, False, False) in kinds  # UAS with a current waypoint
    assert any(t.icao24 == Icao24("abcdef") for t in tracks.values())
    tr, t_end = _random_airspace(3, intruders=False)
    assert all(t.next_waypoint is not None for t in tr.snapshot(t_end)[0].values())


def test_snapshot_and_tracks_of_an_empty_tracker() -> None:
    tr = new_tracker()
    tracks, pred = tr.snapshot(T0)
    assert tracks == {}
    assert pred.points.shape == (0, tr.config.n_points, 4)
    assert tr.tracks() == {}


def test_tracks_are_at_their_own_state_time() -> None:
    tr = new_tracker()
    tr.ingest([meas(0, 0, 100, T0), meas(5, 0, 100, T0 + 0.5, sys_id=2)])
    tracks = tr.tracks()
    assert tracks[TrackId("sysid:1")].t_s == T0
    assert tracks[TrackId("sysid:2")].t_s == T0 + 0.5
    assert tracks[TrackId("sysid:2")].east_m == pytest.approx(5.0)


def _columns(rng: np.random.Generator, n: int) -> dict[str, list[Any]]:
    ids = [TrackId(f"t{i}") for i in range(n)]
    return {
        "id": ids,
        "t_s": rng.uniform(0, 1e9, n).tolist(),
        "lat_deg": rng.uniform(-90, 90, n).tolist(),
        "lon_deg": rng.uniform(-180, 180, n).tolist(),
        "alt_amsl_m": rng.uniform(0, 500, n).tolist(),
        "east_m": rng.normal(size=n).tolist(),
        "north_m": rng.normal(size=n).tolist(),
        "vel_enu_mps": [tuple(v) for v in rng.normal(size=(n, 3)).tolist()],
        "position_sigma_m": rng.uniform(0, 10, n).tolist(),
        "cooperative": (rng.random(n) < 0.5).tolist(),
        "operation_id": [OperationId(f"op{i}") if i % 3 else None for i in range(n)],
        "icao24": [Icao24(f"{i:06x}") if i % 2 else None for i in range(n)],
        "stale": (rng.random(n) < 0.5).tolist(),
        "updates": rng.integers(0, 100, n).tolist(),
        "next_waypoint": [i % 7 if i % 4 else None for i in range(n)],
        "measured_t_s": [float(i) if i % 2 else None for i in range(n)],
    }


@pytest.mark.parametrize("n", [0, 1, 257])
def test_build_tracks_equals_the_dataclass_constructor(n: int) -> None:
    cols = _columns(np.random.default_rng(n), n)
    fast = build_tracks(cols, n)
    plain = [Track(**{f: cols[f][i] for f in FIELDS}) for i in range(n)]
    assert fast == plain
    assert build_tracks(cols, n, fast=False) == plain
    for a, b in zip(fast, plain, strict=True):
        assert type(a) is Track
        assert hash(a) == hash(b)
        assert repr(a) == repr(b)
        assert a.ground_speed_mps == b.ground_speed_mps
    if n:
        with pytest.raises(AttributeError):  # still frozen
            fast[0].east_m = 1.0  # type: ignore[misc]


def test_build_tracks_rejects_wrong_columns() -> None:
    cols = _columns(np.random.default_rng(0), 3)
    with pytest.raises(ValueError, match="'east_m' has 2 rows, expected 3"):
        build_tracks({**cols, "east_m": [0.0, 1.0]}, 3)
    del cols["stale"]
    with pytest.raises(ValueError, match="must be the Track fields"):
        build_tracks(cols, 3)
