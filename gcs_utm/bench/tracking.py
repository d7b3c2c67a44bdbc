"""Tracking throughput: association + Kalman update of N UAS at 1 Hz, and their prediction.

Records:
- ``tracking.ingest``: one second of synthetic measurements (one per UAS; 80 % telemetry
  associated by operation id, 20 % ADS-B associated by ICAO address) through
  :meth:`Tracker.ingest`; ``per_s`` is measurements per second end to end (validation,
  association, WGS84 -> UTM, predict, update). Building the ``Measurement`` objects is the
  adapters' cost and is not timed.
- ``tracking.predict``: :meth:`Tracker.predict` of all N tracks over the configured horizon
  (default 61 points: 0..60 s), plan following included (every UAS is on a plan of
  ``--waypoints`` waypoints, default 10). Steady state: each track's closest segment from the
  previous cycle seeds the windowed search (``window_share`` = tracks answered that way).
- ``tracking.predict_cold``: the same without those hints (every track searches every
  segment of its plan: the first cycle, or tracks far from their plan).
- ``tracking.snapshot``: :meth:`Tracker.snapshot` (N ``Track`` objects + prediction).
- ``tracking.filterpy_update``: the reference, one filterpy ``KalmanFilter`` predict+update
  per measurement in a Python loop, to show what the batched filter replaces.
"""

from __future__ import annotations

import argparse

import numpy as np

from gcs_utm.bench.timing import summary, time_runs
from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Icao24,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    VehicleKind,
    Waypoint4D,
)

NAME = "tracking"
_T0 = 1_700_000_000.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--uas", type=int, default=10_000, help="number of UAS (default 10000)")
    p.add_argument("--runs", type=int, default=9, help="timed repetitions (default 9)")
    p.add_argument("--seed", type=int, default=1, help="random seed of the synthetic fleet")
    p.add_argument(
        "--waypoints", type=int, default=10, help="waypoints per plan, >= 2 (default 10)"
    )


def _fleet(
    frame: LocalFrame, n: int, rng: np.random.Generator, n_wp: int = 10
) -> tuple[list[Operation], np.ndarray, np.ndarray]:
    """N operations on ``n_wp``-waypoint plans at 10 m/s in a 20 km square; returns the
    operations, the waypoint positions (N, n_wp, 3) and times (n_wp,) relative to _T0."""
    starts = rng.uniform(-10_000, 10_000, size=(n, 1, 2))
    legs = rng.normal(size=(n, n_wp - 1, 2))
    legs = legs / np.linalg.norm(legs, axis=2, keepdims=True) * 100.0  # 100 m legs, 10 s each
    en = np.concatenate([starts, starts + np.cumsum(legs, axis=1)], axis=1)
    alt = rng.uniform(60, 120, size=(n, 1, 1)).repeat(n_wp, axis=1)
    pos = np.concatenate([en, alt], axis=2)
    times = np.arange(n_wp) * 10.0
    lat, lon = frame.to_wgs84(pos[:, :, 0], pos[:, :, 1])
    ops = []
    for i in range(n):
        op_id = OperationId(f"op{i}")
        plan = FlightPlan(
            operation_id=op_id,
            version=1,
            waypoints=tuple(
                Waypoint4D(
                    lat_deg=float(lat[i, k]),
                    lon_deg=float(lon[i, k]),
                    alt_amsl_m=float(pos[i, k, 2]),
                    t_s=_T0 + float(times[k]),
                )
                for k in range(n_wp)
            ),
        )
        ops.append(
            Operation(
                id=op_id,
                icao24=Icao24(f"{i:06x}"),
                sys_id=None,
                priority=1,
                plan=plan,
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=10.0,
                flight_geometry_m=10.0,
                operational_volume_m=50.0,
            )
        )
    return ops, pos, times


def _batches(
    frame: LocalFrame, pos: np.ndarray, times: np.ndarray, seconds: int, rng: np.random.Generator
) -> list[list[Measurement]]:
    n = pos.shape[0]
    out = []
    adsb = np.asarray(rng.random(n) < 0.2, dtype=bool)
    for s in range(seconds):
        t = float(s)
        k = min(int(t // 10.0), len(times) - 2)
        frac = (t - times[k]) / (times[k + 1] - times[k])
        p = pos[:, k] + frac * (pos[:, k + 1] - pos[:, k])
        p = p + rng.normal(size=p.shape) * np.array([3.0, 3.0, 5.0])
        lat, lon = frame.to_wgs84(p[:, 0], p[:, 1])
        batch = []
        adsb_list = adsb.tolist()
        for i in range(n):
            is_adsb = bool(adsb_list[i])
            batch.append(
                Measurement(
                    source=MeasurementSource.ADSB if is_adsb else MeasurementSource.TELEMETRY,
                    capture_t_s=_T0 + t + float(rng.uniform(0, 0.9)),
                    receipt_t_s=_T0 + t + 0.95,
                    lat_deg=float(lat[i]),
                    lon_deg=float(lon[i]),
                    alt_amsl_m=float(p[i, 2]),
                    icao24=Icao24(f"{i:06x}") if is_adsb else None,
                    operation_id=None if is_adsb else OperationId(f"op{i}"),
                    eph_m=None if is_adsb else 2.0,
                    epv_m=None if is_adsb else 3.0,
                )
            )
        out.append(batch)
    return out


def _filterpy_record(runs: int) -> dict[str, object]:
    try:  # a development dependency (pip install 'gcs-utm[dev]'), not the service's
        from filterpy.common import Q_discrete_white_noise
        from filterpy.kalman import KalmanFilter
    except ImportError:
        return {
            "benchmark": "tracking.filterpy_update",
            "skipped": "filterpy is not installed: pip install 'gcs-utm[dev]'",
        }

    n_updates = 2_000
    kf = KalmanFilter(dim_x=6, dim_z=3)
    kf.P *= 10.0
    h = np.hstack([np.eye(3), np.zeros((3, 3))])
    r = np.diag([9.0, 9.0, 25.0])
    z = np.zeros(3)

    def loop() -> None:
        for _ in range(n_updates):
            f = np.eye(6)
            f[0:3, 3:6] = np.eye(3)
            q = Q_discrete_white_noise(dim=2, dt=1.0, var=4.0, block_size=3, order_by_dim=False)
            kf.predict(F=f, Q=q)
            kf.update(z, R=r, H=h)

    durations = time_runs(loop, runs=runs, warmup=1)
    return summary("tracking.filterpy_update", n_updates, durations, items_per_run=n_updates)


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    n = int(args.uas)
    runs = int(args.runs)
    n_wp = int(args.waypoints)
    if n_wp < 2:
        raise ValueError(f"--waypoints must be >= 2, got {n_wp}")
    rng = np.random.default_rng(int(args.seed))
    frame = LocalFrame(37.41, -6.0, 10.0)
    ops, pos, times = _fleet(frame, n, rng, n_wp)
    warmup = 2
    batches = _batches(frame, pos, times, warmup + runs, rng)
    tracker = Tracker(frame, TrackingConfig())
    tracker.set_operations(ops)
    it = iter(batches)
    # Each timed run ingests the next second of data, so every run updates existing tracks
    # (the first warm-up creates them).
    ingest_ms = time_runs(lambda: tracker.ingest(next(it)), runs=runs, warmup=warmup)
    counters = tracker.counters
    t_now = _T0 + warmup + runs
    searches = tracker.plan_searches
    predict_ms = time_runs(lambda: tracker.predict(t_now), runs=runs, warmup=1)
    after = tracker.plan_searches
    window = after["window"] - searches["window"]
    full = after["full"] - searches["full"]

    def cold() -> None:
        tracker.forget_plan_hints()
        tracker.predict(t_now)

    cold_ms = time_runs(cold, runs=runs, warmup=1)
    snapshot_ms = time_runs(lambda: tracker.snapshot(t_now), runs=runs, warmup=1)
    points = tracker.config.n_points
    return [
        summary(
            "tracking.ingest",
            n,
            ingest_ms,
            items_per_run=n,
            accepted=counters["accepted"],
            rejected=sum(counters[k] for k in ("out_of_order", "duplicate", "invalid", "gate")),
        ),
        summary(
            "tracking.predict",
            n,
            predict_ms,
            items_per_run=n,
            points=points,
            waypoints=n_wp,
            window_share=round(window / max(window + full, 1), 4),
        ),
        summary("tracking.predict_cold", n, cold_ms, items_per_run=n, points=points),
        summary("tracking.snapshot", n, snapshot_ms, items_per_run=n, points=points),
        _filterpy_record(runs),
    ]
