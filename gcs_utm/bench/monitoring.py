"""Monitoring cycle on synthetic traffic (prediction + conformance + geofences + separation).

Traffic: N UAS uniform in a 50 km x 50 km box, 0-150 m AMSL, 1-30 m/s with random heading
and +-2 m/s climb; 60 s horizon at 1 s; 100 geofences (half cylinders r 200-1000 m, half
star/U-like concave polygons). Prediction stage: a vectorised constant-velocity prediction
written here (not Tracker.predict). The separation stage uses ``detect_los`` (all-pairs below
``allpairs_below``, the 4D grid above). At N = 2,000 the brute-force oracle is timed in the
same run on the same traffic and the pair sets are compared.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from gcs_utm.bench.timing import summary, time_runs
from gcs_utm.core.monitoring import MonitoringConfig, detect_los, detect_los_bruteforce
from gcs_utm.core.monitoring.checks import check_geofences, pack_plans, plan_distance
from gcs_utm.core.monitoring.fences import LocalFence
from gcs_utm.core.monitoring.geometry import FloatArray, ring_edges
from gcs_utm.model import GeofenceId

NAME = "monitoring"
BOX_M = 50_000.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--uas", type=int, action="append", help="N (repeatable); default 1k..50k")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--oracle-n", type=int, default=2000, help="0 disables the oracle run")


def _fences(rng: np.random.Generator) -> list[LocalFence]:
    out = []
    for i in range(100):
        cx, cy = rng.uniform(0, BOX_M, 2)
        zlo = float(rng.uniform(0, 60))
        zhi = zlo + float(rng.uniform(40, 150))
        if i % 2 == 0:
            r = float(rng.uniform(200, 1000))
            out.append(
                LocalFence(
                    id=GeofenceId(f"c{i}"),
                    edges=None,
                    center=(cx, cy),
                    radius_m=r,
                    z_lo=zlo,
                    z_hi=zhi,
                    t_lo=-math.inf,
                    t_hi=math.inf,
                    bbox=(cx - r, cy - r, cx + r, cy + r),
                )
            )
        else:
            k = 10
            ang = np.linspace(0, 2 * np.pi, k, endpoint=False)
            rad = np.where(np.arange(k) % 2 == 0, 800.0, 300.0)  # star: concave
            vx = cx + rad * np.cos(ang)
            vy = cy + rad * np.sin(ang)
            out.append(
                LocalFence(
                    id=GeofenceId(f"p{i}"),
                    edges=ring_edges(vx, vy),
                    center=None,
                    radius_m=0.0,
                    z_lo=zlo,
                    z_hi=zhi,
                    t_lo=float(rng.uniform(0, 30)),
                    t_hi=math.inf,
                    bbox=(vx.min(), vy.min(), vx.max(), vy.max()),
                )
            )
    return out


def _traffic(n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    pos = np.column_stack(
        [rng.uniform(0, BOX_M, n), rng.uniform(0, BOX_M, n), rng.uniform(0, 150, n)]
    )
    speed = rng.uniform(1, 30, n)  # m/s
    hdg = rng.uniform(0, 2 * np.pi, n)  # rad
    vel = np.column_stack([speed * np.sin(hdg), speed * np.cos(hdg), rng.uniform(-2, 2, n)])
    return pos, vel


def _predict(pos: FloatArray, vel: FloatArray, t_s: float) -> FloatArray:
    k = np.arange(61, dtype=np.float64)  # s, 60 s horizon at 1 s
    pts = np.empty((len(pos), 61, 4))
    pts[:, :, :3] = pos[:, None, :] + vel[:, None, :] * k[None, :, None]  # m
    pts[:, :, 3] = t_s + k  # s
    return pts


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    sizes = args.uas or [1000, 2000, 5000, 10000, 20000, 50000]
    cfg = MonitoringConfig()
    rng = np.random.default_rng(args.seed)
    fences = _fences(rng)
    records: list[dict[str, object]] = []
    medians: dict[int, float] = {}
    for n in sizes:
        pos, vel = _traffic(n, rng)
        ov = np.full(n, 20.0)  # m, operational volume
        # Plans: the straight 4D line each UAS flies (conformance distance computed for all).
        plans = pack_plans(
            [np.array([[*p, 0.0], [*(p + 60 * v), 60.0]]) for p, v in zip(pos, vel, strict=True)]
        )
        found: dict[str, int] = {}

        def cycle(
            pos: FloatArray = pos,
            vel: FloatArray = vel,
            ov: FloatArray = ov,
            plans: object = plans,
            found: dict[str, int] = found,
        ) -> None:
            pts = _predict(pos, vel, 0.0)
            plan_distance(plans, pos, np.zeros(len(pos)), 30.0)  # type: ignore[arg-type]
            found["geofence"] = len(check_geofences(pts, fences))
            found["los"] = len(detect_los(pts, ov, cfg))

        ms = time_runs(cycle, runs=args.runs)
        rec = summary(
            "monitoring.cycle",
            n,
            ms,
            items_per_run=n,
            prediction="constant-velocity (bench)",
            geofences=len(fences),
            los_pairs=found["los"],
            geofence_hits=found["geofence"],
            method="allpairs" if n < cfg.allpairs_below else "grid",
        )
        medians[n] = float(rec["median_ms"])  # type: ignore[arg-type]
        records.append(rec)
        if args.oracle_n and n == args.oracle_n:
            pts = _predict(pos, vel, 0.0)
            oracle_pairs: list[set[tuple[int, int]]] = []

            def fast_fn(pts: FloatArray = pts, ov: FloatArray = ov) -> None:
                detect_los(pts, ov, cfg)

            def brute_fn(
                pts: FloatArray = pts,
                ov: FloatArray = ov,
                sink: list[set[tuple[int, int]]] = oracle_pairs,
            ) -> None:
                sink.append({(x.a, x.b) for x in detect_los_bruteforce(pts, ov, cfg)})

            fast = time_runs(fast_fn, runs=args.runs)
            brute = time_runs(brute_fn, runs=1, warmup=0)
            fast_pairs = {(x.a, x.b) for x in detect_los(pts, ov, cfg)}
            records.append(summary("monitoring.separation_fast", n, fast))
            records.append(
                summary(
                    "monitoring.separation_bruteforce",
                    n,
                    brute,
                    same_pairs=fast_pairs == oracle_pairs[0],
                    pairs=len(fast_pairs),
                    ratio=round(brute[0] / float(np.median(fast)), 1),
                )
            )
    if len(medians) >= 2:
        ns = np.array(sorted(medians), dtype=float)
        ts = np.array([medians[int(k)] for k in ns])
        slope = float(np.polyfit(np.log(ns), np.log(ts), 1)[0])
        records.append(
            {
                "benchmark": "monitoring.scaling",
                "n": int(ns[-1]),
                "runs": args.runs,
                "median_ms": medians[int(ns[-1])],
                "min_ms": min(ts),
                "max_ms": max(ts),
                "fitted_exponent": round(slope, 3),
            }
        )
    return records
