"""Strategic (pre-flight) check of filed plans on the space-time index.

Airspace (issue 24): N operations over a 20 km x 20 km area within 15 minutes; each plan
has 3-6 waypoints, legs of 30-120 s at 5-20 m/s in a random direction (kept inside the
area), 30-120 m above ground per waypoint, operational volume 10 m; the default minima
(50 m horizontal, 15 m vertical) and a 1 s sampling step (``gcs-utm scenario check``'s).

Records:
- ``strategic.all_pairs``: ``strategic_check`` of the N plans (every pair in conflict;
  no geofences), with the number of conflicts and of pairs the index left for the exact check.
- ``strategic.one_vs_n``: ONE new plan checked against the N filed ones
  (``FiledPlans.check``), the call a filing operator waits for; each run a different new
  plan (``--queries`` of them), the filed plans indexed once beforehand (and not re-checked).
- ``strategic.file_one``: filing one plan into the index (``FiledPlans.add``).

The dense profile (:mod:`.strategic_cli`, ``--dense-plans``): ``gcs-utm scenario check`` of
a denser airspace end to end (load, check, JSON report), in a fresh process as a user runs it,
and the same stages in this process. ``--profile index`` or ``--profile dense`` runs one part.
"""

from __future__ import annotations

import argparse

import numpy as np

from gcs_utm.bench import strategic_cli
from gcs_utm.bench.timing import summary, time_runs
from gcs_utm.core.monitoring import MonitoringConfig, strategic_check
from gcs_utm.core.monitoring.plan_index import candidate_pairs, grid_cell_m, growth_m, window_boxes
from gcs_utm.core.monitoring.strategic import FiledPlans, plans_local
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Operation, OperationId, VehicleKind, Waypoint4D

NAME = "strategic"
AREA_M = 20_000.0
WINDOW_S = 900.0
_T0 = 1_700_000_000.0  # s
_FRAME = LocalFrame(37.41, -6.0, 0.0)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plans", "--n", type=int, action="append", help="N filed plans (repeatable)")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--queries", type=int, default=30, help="one-vs-N checks timed per N")
    p.add_argument("--seed", type=int, default=11)
    p.add_argument("--profile", choices=("all", "index", "dense"), default="all")
    strategic_cli.add_arguments(p)


def random_operations(n: int, seed: int, *, prefix: str = "op") -> list[Operation]:
    """The airspace of the module doc: ``n`` operations, deterministic for ``seed``."""
    rng = np.random.default_rng(seed)
    out: list[Operation] = []
    for i in range(n):
        k = int(rng.integers(3, 7))
        leg_s = rng.uniform(30, 120, k - 1)
        speed = rng.uniform(5, 20, k - 1)
        hdg = rng.uniform(0, 2 * np.pi, k - 1)
        step = np.column_stack([np.sin(hdg), np.cos(hdg)]) * (speed * leg_s)[:, None]
        xy = np.cumsum(np.vstack([rng.uniform(0, AREA_M, 2), step]), axis=0)
        xy = np.clip(xy, 0.0, AREA_M) - AREA_M / 2
        dt = np.concatenate([[0.0], np.cumsum(leg_s)])
        t = _T0 + float(rng.uniform(0, max(WINDOW_S - dt[-1], 0.0))) + dt
        lat, lon = _FRAME.to_wgs84(xy[:, 0], xy[:, 1])
        alt = rng.uniform(30, 120, k)
        op_id = OperationId(f"{prefix}{i}")
        wps = tuple(
            Waypoint4D(lat_deg=float(a), lon_deg=float(o), alt_amsl_m=float(z), t_s=float(s))
            for a, o, z, s in zip(lat, lon, alt, t, strict=True)
        )
        out.append(
            Operation(
                id=op_id,
                icao24=None,
                sys_id=None,
                priority=1,
                plan=FlightPlan(operation_id=op_id, version=1, waypoints=wps),
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=float(speed.mean()),
                flight_geometry_m=5.0,
                operational_volume_m=10.0,
            )
        )
    return out


def _candidates(ops: list[Operation], cfg: MonitoringConfig) -> int:
    local = plans_local([o.plan for o in ops], _FRAME)
    volume = np.array([o.operational_volume_m for o in ops])
    boxes = window_boxes(local, growth_m(cfg, volume), max(cfg.grid_dt_s, 1.0))
    return len(candidate_pairs(boxes, len(ops), grid_cell_m(cfg, boxes)))


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    records = _index_records(args) if args.profile in ("all", "index") else []
    if args.profile in ("all", "dense"):
        records += strategic_cli.run(args)
    return records


def _index_records(args: argparse.Namespace) -> list[dict[str, object]]:
    sizes = args.plans or [2000, 10000]
    cfg = MonitoringConfig()
    records: list[dict[str, object]] = []
    for n in sizes:
        ops = random_operations(n, args.seed)
        found: list[int] = []

        def all_pairs(ops: list[Operation] = ops, found: list[int] = found) -> None:
            found.append(len(strategic_check(ops, (), _FRAME, cfg).conflicts))

        ms = time_runs(all_pairs, runs=args.runs)
        records.append(
            summary(
                "strategic.all_pairs",
                n,
                ms,
                items_per_run=n,
                conflicts=found[-1],
                exact_pairs=_candidates(ops, cfg),
                pairs=n * (n - 1) // 2,
            )
        )
        filed = FiledPlans(_FRAME, cfg)
        filed.add_many(ops)
        new = random_operations(args.queries + 1, args.seed + 1, prefix="new")
        queue = iter(new)
        hits: list[int] = []

        def one(filed: FiledPlans = filed, queue: object = queue, hits: list[int] = hits) -> None:
            op = next(queue)  # type: ignore[call-overload]
            hits.append(len(filed.check(op.plan, op)))

        ms = time_runs(one, runs=args.queries)
        records.append(
            summary(
                "strategic.one_vs_n",
                n,
                ms,
                conflicts_per_plan=round(float(np.mean(hits)), 2),
            )
        )
        adds = iter(random_operations(args.queries + 1, args.seed + 2, prefix="add"))

        def file_one(filed: FiledPlans = filed, adds: object = adds) -> None:
            filed.add(next(adds))  # type: ignore[call-overload]

        ms = time_runs(file_one, runs=args.queries)
        records.append(summary("strategic.file_one", n, ms))
    return records
