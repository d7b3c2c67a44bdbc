"""Monitoring cycle on synthetic traffic (prediction + conformance + geofences + separation).

Traffic (issue 4): N UAS uniform in a 50 km x 50 km box, 0-150 m AMSL, 1-30 m/s with random
heading and +-2 m/s climb, each flying a filed straight 4D plan along its velocity; 60 s
horizon at 1 s (the tracking defaults); 100 geofences (half cylinders r 200-1000 m, half
10-point concave stars, activating 0-30 s into the horizon), each a ``Geofence`` in WGS84.

The traffic lives in a real :class:`Tracker` (two position fixes per UAS ingested before
timing), and the prediction timed is the production one, ``Tracker.predict`` (plan following
and covariance growth included), exactly what the monitoring service gets each cycle.

Records:
- ``monitoring.cycle``: ``Tracker.predict`` + conformance (``plan_distance`` on the packed
  plans) + geofences (``check_geofences``) + separation (``detect_los``: all-pairs below
  ``allpairs_below``, the 4D grid above), the window bounds shared between the last two as
  ``Monitor`` does. The array path of one cycle.
- ``monitoring.service_cycle``: what ``MonitoringService.run_once`` does: ``Tracker.snapshot``
  (N ``Track`` objects + prediction), the ``AirspaceSnapshot``, and ``Monitor.cycle`` (the
  same kernels plus the per-operation threat bookkeeping). Each run after the warm-up is
  the steady state: the same threats persist (updated, not re-raised).
- ``--density-of N0``: the box side grows with sqrt(N / N0) and the number of geofences
  with N / N0, so every N has the traffic density (and so the conflicts per UAS) of N0 UAS
  in the 50 km box; without it every N shares the one box, and true conflicts grow as N^2.
- at N = ``--oracle-n`` the separation stage alone against the brute-force oracle on the same
  prediction (same pairs?, ratio); ``monitoring.scaling``: fitted exponent of each cycle.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from gcs_utm.bench.timing import summary, time_runs
from gcs_utm.core.monitoring import Monitor, MonitoringConfig, detect_los, detect_los_bruteforce
from gcs_utm.core.monitoring.checks import check_geofences, pack_plans, plan_distance
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.geometry import FloatArray, window_extents
from gcs_utm.core.monitoring.separation import window_steps
from gcs_utm.core.monitoring.strategic import plan_local
from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    VehicleKind,
    Waypoint4D,
)

NAME = "monitoring"
BOX_M = 50_000.0
_T0 = 1_700_000_000.0  # s, the cycle time
_FRAME = LocalFrame(37.41, -6.0, 0.0)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--uas", "--n", type=int, action="append", help="N (repeatable)")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--oracle-n", type=int, default=2000, help="0 disables the oracle run")
    p.add_argument(
        "--no-service", action="store_true", help="skip the monitoring.service_cycle records"
    )
    p.add_argument(
        "--density-of",
        type=int,
        default=0,
        metavar="N0",
        help="keep the traffic density of N0 UAS in the 50 km box: the box side grows with "
        "sqrt(N / N0) and the geofences with N / N0 (default: one 50 km box for every N)",
    )


def _latlon(e: float, n: float) -> LatLon:
    lat, lon = _FRAME.point_to_wgs84(e, n)
    return LatLon(lat_deg=lat, lon_deg=lon)


def _fences(rng: np.random.Generator, box_m: float = BOX_M, count: int = 100) -> list[Geofence]:
    out = []
    half = box_m / 2
    for i in range(count):
        cx, cy = rng.uniform(-half, half, 2)
        zlo = float(rng.uniform(0, 60))
        zhi = zlo + float(rng.uniform(40, 150))
        if i % 2 == 0:
            out.append(
                Geofence(
                    id=GeofenceId(f"c{i}"),
                    shape=GeofenceShape.CYLINDER,
                    min_alt_amsl_m=zlo,
                    max_alt_amsl_m=zhi,
                    center=_latlon(cx, cy),
                    radius_m=float(rng.uniform(200, 1000)),
                )
            )
        else:
            ang = np.linspace(0, 2 * np.pi, 10, endpoint=False)
            rad = np.where(np.arange(10) % 2 == 0, 800.0, 300.0)  # star: concave
            out.append(
                Geofence(
                    id=GeofenceId(f"p{i}"),
                    shape=GeofenceShape.POLYGON,
                    min_alt_amsl_m=zlo,
                    max_alt_amsl_m=zhi,
                    vertices=tuple(
                        _latlon(cx + r * math.cos(a), cy + r * math.sin(a))
                        for a, r in zip(ang, rad, strict=True)
                    ),
                    start_t_s=_T0 + float(rng.uniform(0, 30)),
                )
            )
    return out


def _traffic(
    n: int, rng: np.random.Generator, box_m: float = BOX_M
) -> tuple[list[Operation], list[Measurement]]:
    """N operations on straight 4D plans (from 100 s before to 200 s after the cycle time)
    and two exact position fixes per UAS (1 s and 0 s before the cycle time)."""
    half = box_m / 2
    pos = np.column_stack(
        [rng.uniform(-half, half, n), rng.uniform(-half, half, n), rng.uniform(0, 150, n)]
    )
    speed = rng.uniform(1, 30, n)  # m/s
    hdg = rng.uniform(0, 2 * np.pi, n)  # rad
    vel = np.column_stack([speed * np.sin(hdg), speed * np.cos(hdg), rng.uniform(-2, 2, n)])
    wp_dt = np.array([-100.0, 200.0])  # s, plan waypoints relative to _T0
    fix_dt = np.array([-1.0, 0.0])  # s, the two fixes
    wp = pos[:, None, :] + vel[:, None, :] * wp_dt[None, :, None]  # m, (N, 2, 3)
    fx = pos[:, None, :] + vel[:, None, :] * fix_dt[None, :, None]
    wlat, wlon = _FRAME.to_wgs84(wp[:, :, 0], wp[:, :, 1])
    flat, flon = _FRAME.to_wgs84(fx[:, :, 0], fx[:, :, 1])
    ops: list[Operation] = []
    meas: list[Measurement] = []
    for i in range(n):
        op_id = OperationId(f"op{i}")
        plan = FlightPlan(
            operation_id=op_id,
            version=1,
            waypoints=tuple(
                Waypoint4D(
                    lat_deg=float(wlat[i, k]),
                    lon_deg=float(wlon[i, k]),
                    alt_amsl_m=float(wp[i, k, 2]),
                    t_s=_T0 + float(wp_dt[k]),
                )
                for k in range(2)
            ),
        )
        ops.append(
            Operation(
                id=op_id,
                icao24=None,
                sys_id=None,
                priority=1,
                plan=plan,
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=float(speed[i]),
                flight_geometry_m=10.0,
                operational_volume_m=20.0,
            )
        )
        for k in range(2):
            meas.append(
                Measurement(
                    source=MeasurementSource.TELEMETRY,
                    capture_t_s=_T0 + float(fix_dt[k]),
                    receipt_t_s=_T0 + float(fix_dt[k]) + 0.05,
                    lat_deg=float(flat[i, k]),
                    lon_deg=float(flon[i, k]),
                    alt_amsl_m=float(fx[i, k, 2]),
                    vel_ned_mps=(float(vel[i, 1]), float(vel[i, 0]), -float(vel[i, 2])),
                    eph_m=1.0,
                    epv_m=2.0,
                    operation_id=op_id,
                )
            )
    return ops, meas


class _Setup:
    """One fleet in a tracker, the fences, and the inputs of the array path."""

    def __init__(
        self, n: int, fences: list[Geofence], rng: np.random.Generator, box_m: float = BOX_M
    ) -> None:
        self.cfg = MonitoringConfig()
        self.fences = fences
        self.ops, meas = _traffic(n, rng, box_m)
        self.tracker = Tracker(_FRAME, TrackingConfig())
        self.tracker.set_operations(self.ops)
        self.tracker.ingest(meas[0::2])
        self.tracker.ingest(meas[1::2])
        tracks = self.tracker.tracks()
        ids = self.tracker.predict(_T0).track_ids
        op_of = {tid: tr.operation_id for tid, tr in tracks.items()}
        by_id = {o.id: o for o in self.ops}
        self.rows_ops = [by_id[op_of[tid]] for tid in ids]  # type: ignore[index]
        self.ov = np.array([o.operational_volume_m for o in self.rows_ops])
        self.pos = np.array(
            [[tracks[t].east_m, tracks[t].north_m, tracks[t].alt_amsl_m] for t in ids]
        )
        self.plans = pack_plans([plan_local(o.plan, _FRAME) for o in self.rows_ops])
        self.local_fences = [localise(g, _FRAME) for g in fences]
        self.found: dict[str, int] = {}

    def cycle(self) -> None:
        """The array path: production prediction, conformance, geofences, separation."""
        pts = self.tracker.predict(_T0).points
        plan_distance(self.plans, self.pos, np.full(len(self.pos), _T0), 30.0)
        windows = window_extents(pts, window_steps(pts, self.cfg))
        self.found["geofence"] = len(check_geofences(pts, self.local_fences, windows))
        self.found["los"] = len(detect_los(pts, self.ov, self.cfg, windows))

    def service_cycle(self) -> None:
        """``MonitoringService.run_once``: tracker snapshot -> AirspaceSnapshot -> Monitor."""
        tracks, prediction = self.tracker.snapshot(_T0)
        snap = AirspaceSnapshot(
            t_s=_T0,
            operations=self.operations,
            tracks=tracks,
            geofences=tuple(self.fences),
            prediction=prediction,
        )
        self.monitor.cycle(snap)
        # counted, not built: the service itself never reads them all each cycle
        self.found["threats"] = self.monitor.open_count()

    def prepare_service(self) -> None:
        self.operations = {o.id: o for o in self.ops}
        self.monitor = Monitor(_FRAME, self.cfg)


def _exponent(medians: dict[int, float]) -> float:
    ns = np.array(sorted(medians), dtype=float)
    ts = np.array([medians[int(k)] for k in ns])
    return round(float(np.polyfit(np.log(ns), np.log(ts), 1)[0]), 3)


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    sizes = args.uas or [1000, 2000, 5000, 10000, 20000, 50000]
    rng = np.random.default_rng(args.seed)
    base_fences = _fences(rng)
    n0 = args.density_of
    records: list[dict[str, object]] = []
    medians: dict[str, dict[int, float]] = {"monitoring.cycle": {}, "monitoring.service_cycle": {}}
    for n in sizes:
        box_m = BOX_M * math.sqrt(n / n0) if n0 and n > n0 else BOX_M
        fences = base_fences
        if box_m != BOX_M:
            fences = _fences(rng, box_m, round(100 * box_m**2 / BOX_M**2))
        s = _Setup(n, fences, rng, box_m)
        ms = time_runs(s.cycle, runs=args.runs)
        rec = summary(
            "monitoring.cycle",
            n,
            ms,
            items_per_run=n,
            prediction="Tracker.predict",
            geofences=len(fences),
            los_pairs=s.found["los"],
            box_km=round(box_m / 1000.0, 1),
            geofence_hits=s.found["geofence"],
            method="allpairs" if n < s.cfg.allpairs_below else "grid",
        )
        medians["monitoring.cycle"][n] = float(rec["median_ms"])  # type: ignore[arg-type]
        records.append(rec)
        if not args.no_service:
            s.prepare_service()
            ms = time_runs(s.service_cycle, runs=args.runs)
            rec = summary(
                "monitoring.service_cycle",
                n,
                ms,
                items_per_run=n,
                prediction="Tracker.snapshot",
                threats=s.found["threats"],
                box_km=round(box_m / 1000.0, 1),
                geofences=len(fences),
            )
            medians["monitoring.service_cycle"][n] = float(rec["median_ms"])  # type: ignore[arg-type]
            records.append(rec)
        if args.oracle_n and n == args.oracle_n:
            records += _oracle(s, args.runs)
    for name, med in medians.items():
        if len(med) >= 2:
            top = max(med)
            records.append(
                {
                    "benchmark": "monitoring.scaling",
                    "of": name,
                    "n": top,
                    "runs": args.runs,
                    "median_ms": med[top],
                    "min_ms": min(med.values()),
                    "max_ms": max(med.values()),
                    "fitted_exponent": _exponent(med),
                }
            )
    return records


def _oracle(s: _Setup, runs: int) -> list[dict[str, object]]:
    pts: FloatArray = s.tracker.predict(_T0).points
    n = len(pts)
    oracle: list[set[tuple[int, int]]] = []

    def fast_fn() -> None:
        detect_los(pts, s.ov, s.cfg)

    def brute_fn() -> None:
        oracle.append({(x.a, x.b) for x in detect_los_bruteforce(pts, s.ov, s.cfg)})

    fast = time_runs(fast_fn, runs=runs)
    brute = time_runs(brute_fn, runs=1, warmup=0)
    fast_pairs = {(x.a, x.b) for x in detect_los(pts, s.ov, s.cfg)}
    return [
        summary("monitoring.separation_fast", n, fast),
        summary(
            "monitoring.separation_bruteforce",
            n,
            brute,
            same_pairs=fast_pairs == oracle[0],
            pairs=len(fast_pairs),
            ratio=round(brute[0] / float(np.median(fast)), 1),
        ),
    ]
