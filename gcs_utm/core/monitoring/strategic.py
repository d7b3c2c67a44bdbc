"""Strategic check of filed 4D plans: plan against plan, plan against geofence.

Plans are piecewise linear in time between their waypoints (WGS84/AMSL, POSIX t_s), converted
to the local frame. Two plans are compared over the time both are airborne, on the merged set
of both plans' waypoint times plus a ``step_s`` grid: between two consecutive merged times
both UAS move linearly, so the exact segment kernel gives the exact first loss and closest
approach (the grid only adds samples; it never decides a result).

Separation: per pair, ``MonitoringConfig.effective_minima`` (never below the sum of the two
operational-volume radii). A plan is checked against a geofence after growing the fence by the
plan's operational-volume radius (``fences.localise``): a plan closer than that radius to an
active fence counts as crossing.

Which pairs are checked exactly: those the space-time index of :mod:`.plan_index` cannot rule
out (Monitoring's grid per time window for all pairs, the per-window slice for one plan
against the filed ones). The index is conservative, so the results are those of checking
every pair; ``tests/monitoring/strategic_oracle.py`` is that every-pair reference and the
tests compare the two on random airspaces. :class:`FiledPlans` keeps the filed plans of a
running service indexed, so filing one plan checks it against the others without
re-checking them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs_utm.core.monitoring import end_circle
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import LocalFence, localise
from gcs_utm.core.monitoring.geometry import FloatArray
from gcs_utm.core.monitoring.pair_check import PairFigures, check_pairs
from gcs_utm.core.monitoring.plan_index import (
    PlanIndex,
    candidate_pairs,
    grid_cell_m,
    growth_m,
    window_boxes,
    window_s_of,
)
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Geofence, GeofenceId, Operation, OperationId


@dataclass(frozen=True, slots=True, kw_only=True)
class PlanConflict:
    """Loss of separation between two filed plans. ``min_distance_m`` is the 3D closest
    approach at ``closest_t_s``; ``min_horizontal_m``/``min_vertical_m`` are the smallest
    horizontal and vertical distances over the common time span (each at its own instant)."""

    a: OperationId
    b: OperationId
    first_loss_t_s: float
    closest_t_s: float
    min_distance_m: float
    min_horizontal_m: float
    min_vertical_m: float


@dataclass(frozen=True, slots=True, kw_only=True)
class PlanGeofenceCrossing:
    operation_id: OperationId
    geofence_id: GeofenceId
    entry_t_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class StrategicReport:
    conflicts: tuple[PlanConflict, ...]
    crossings: tuple[PlanGeofenceCrossing, ...]


def plan_local(plan: FlightPlan, frame: LocalFrame) -> FloatArray:
    """(K, 4) east_m, north_m, alt_amsl_m, t_s of the plan's waypoints."""
    lat = np.array([w.lat_deg for w in plan.waypoints])
    lon = np.array([w.lon_deg for w in plan.waypoints])
    e, n = frame.to_local(lat, lon)
    z = np.array([w.alt_amsl_m for w in plan.waypoints])
    t = np.array([w.t_s for w in plan.waypoints])
    return np.column_stack([e, n, z, t])


def plans_local(plans: Sequence[FlightPlan], frame: LocalFrame) -> list[FloatArray]:
    """:func:`plan_local` of many plans with one frame conversion (the same numbers: the
    conversion is point by point)."""
    if not plans:
        return []
    counts = [len(p.waypoints) for p in plans]
    wps = [w for p in plans for w in p.waypoints]
    lat = np.fromiter((w.lat_deg for w in wps), np.float64, len(wps))
    lon = np.fromiter((w.lon_deg for w in wps), np.float64, len(wps))
    e, n = frame.to_local(lat, lon)
    z = np.fromiter((w.alt_amsl_m for w in wps), np.float64, len(wps))
    t = np.fromiter((w.t_s for w in wps), np.float64, len(wps))
    table = np.column_stack([e, n, z, t])
    return np.split(table, np.cumsum(counts)[:-1])


@dataclass(frozen=True, slots=True)
class _Pair:
    """One pair for the exact check: both plans' local points, ids and the pair's minima."""

    pa: FloatArray
    pb: FloatArray
    ida: OperationId
    idb: OperationId
    min_h: float
    min_v: float


def _pair_conflicts(
    pairs: Sequence[_Pair], *, spherical: bool, step_s: float
) -> list[PlanConflict | None]:
    """The exact check of each pair (None: no conflict), all pairs at once
    (:func:`.pair_check.check_pairs`)."""
    local: list[FloatArray] = []
    slots: dict[int, int] = {}
    index = np.empty((len(pairs), 2), np.int64)
    for k, pair in enumerate(pairs):
        for side, pts in enumerate((pair.pa, pair.pb)):
            if id(pts) not in slots:
                slots[id(pts)] = len(local)
                local.append(pts)
            index[k, side] = slots[id(pts)]
    found = check_pairs(
        local,
        index[:, 0],
        index[:, 1],
        np.array([p.min_h for p in pairs], np.float64),
        np.array([p.min_v for p in pairs], np.float64),
        spherical=spherical,
        step_s=step_s,
    )
    out: list[PlanConflict | None] = [None] * len(pairs)
    for k in np.flatnonzero(found.conflict).tolist():
        out[k] = _conflict(found, k, pairs[k].ida, pairs[k].idb)
    return out


def _conflict(found: PairFigures, k: int, ida: OperationId, idb: OperationId) -> PlanConflict:
    return PlanConflict(
        a=ida,
        b=idb,
        first_loss_t_s=float(found.first_loss_t_s[k]),
        closest_t_s=float(found.closest_t_s[k]),
        min_distance_m=float(found.min_distance_m[k]),
        min_horizontal_m=float(found.min_horizontal_m[k]),
        min_vertical_m=float(found.min_vertical_m[k]),
    )


def _fence_crossing(pts: FloatArray, fence: LocalFence) -> float | None:
    if not fence.active_between(float(pts[0, 3]), float(pts[-1, 3])):
        return None
    if len(pts) == 1:
        pts = np.vstack([pts, pts])
    lo = pts[:, :2].min(axis=0)
    hi = pts[:, :2].max(axis=0)
    bx = fence.bbox
    if lo[0] > bx[2] or lo[1] > bx[3] or hi[0] < bx[0] or hi[1] < bx[1]:
        return None
    s = fence.first_entry(pts[:-1], pts[1:])
    finite = np.isfinite(s)
    if not finite.any():
        return None
    k = int(np.argmax(finite))  # segments are in time order: the first finite is the entry
    return float(pts[k, 3] + s[k] * (pts[k + 1, 3] - pts[k, 3]))


def plan_vs_plans(
    plan: FlightPlan,
    op: Operation,
    others: Sequence[Operation],
    frame: LocalFrame,
    config: MonitoringConfig,
    *,
    step_s: float = 1.0,
) -> list[PlanConflict]:
    """Conflicts of ``plan`` (flown by ``op``, using op's operational volume) with the current
    plans of ``others`` (``op`` itself is skipped), in the order of ``others``.
    ``PlanConflict.a`` is ``op.id``."""
    rest = [o for o in others if o.id != op.id]
    if not rest:
        return []
    index = FiledPlans(frame, config, step_s=step_s)
    index.add_many(rest)
    return index.check(plan, op)


def plan_vs_geofences(
    plan: FlightPlan,
    op: Operation,
    geofences: Sequence[Geofence],
    frame: LocalFrame,
    config: MonitoringConfig,
) -> list[PlanGeofenceCrossing]:
    """Active geofences (space and time) that ``plan`` crosses or passes closer to than
    ``op.operational_volume_m``, or that a fixed wing's circle round the plan's last
    waypoint enters (:mod:`.end_circle`), with the first such time."""
    del config  # the inflation is the operation's own volume; kept for a uniform signature
    pts = plan_local(plan, frame)
    # A fixed wing's circle after the plan, against the fence as Monitoring checks it.
    ring = end_circle.end_ring(pts, end_circle.circle_radius_m(op), end_circle.loiter_radius_m(op))
    out: list[PlanGeofenceCrossing] = []
    for g in geofences:
        if not g.applies_to(op.id):
            continue
        t = _fence_crossing(pts, localise(g, frame, op.operational_volume_m))
        if t is None and ring is not None:
            t = end_circle.ring_entry(ring, localise(g, frame))
        if t is not None:
            out.append(PlanGeofenceCrossing(operation_id=op.id, geofence_id=g.id, entry_t_s=t))
    return out


def strategic_check(
    operations: Sequence[Operation],
    geofences: Sequence[Geofence],
    frame: LocalFrame,
    config: MonitoringConfig,
    *,
    step_s: float = 1.0,
) -> StrategicReport:
    """Every pair of filed plans against each other, and every plan against every geofence.
    Pairs are reported once, ``a`` before ``b`` in the order of ``operations``."""
    local = plans_local([op.plan for op in operations], frame)
    return StrategicReport(
        conflicts=tuple(_all_pair_conflicts(operations, local, config, step_s)),
        crossings=tuple(_crossings(operations, local, geofences, frame)),
    )


def _all_pair_conflicts(
    operations: Sequence[Operation],
    local: list[FloatArray],
    config: MonitoringConfig,
    step_s: float,
) -> list[PlanConflict]:
    n = len(operations)
    if n < 2:
        return []
    volume = np.array([op.operational_volume_m for op in operations], np.float64)
    boxes = window_boxes(local, growth_m(config, volume), window_s_of(config, step_s))
    codes = candidate_pairs(boxes, n, grid_cell_m(config, boxes))
    ia, ib = codes // n, codes % n
    # the pairs' minima, one effective_minima call per distinct pair of volumes
    vols, inverse = np.unique(
        np.stack([volume[ia], volume[ib]], axis=1), axis=0, return_inverse=True
    )
    minima = np.array([config.effective_minima(va, vb) for va, vb in vols.tolist()]).reshape(-1, 2)
    mh, mv = minima[inverse.ravel(), 0], minima[inverse.ravel(), 1]
    found = check_pairs(local, ia, ib, mh, mv, spherical=config.spherical, step_s=step_s)
    return [
        _conflict(found, k, operations[i].id, operations[j].id)
        for k, i, j in zip(
            np.flatnonzero(found.conflict).tolist(),
            ia[found.conflict].tolist(),
            ib[found.conflict].tolist(),
            strict=True,
        )
    ]


def _crossings(
    operations: Sequence[Operation],
    local: list[FloatArray],
    geofences: Sequence[Geofence],
    frame: LocalFrame,
) -> list[PlanGeofenceCrossing]:
    """Every plan against every geofence, in (operation, geofence) order; the exact test runs
    only where the plan's horizontal box meets the fence's box grown by the plan's volume
    (the test's own first rejection, done for all pairs at once)."""
    if not operations or not geofences:
        return []
    volume = np.array([op.operational_volume_m for op in operations], np.float64)
    plo = np.array([p[:, :2].min(axis=0) for p in local])  # (N, 2) m
    phi = np.array([p[:, :2].max(axis=0) for p in local])
    fences: dict[tuple[int, float], LocalFence] = {}
    near: list[tuple[int, int]] = []
    for k, g in enumerate(geofences):
        for vol in np.unique(volume).tolist():
            fences[k, vol] = localise(g, frame, vol)
        bx = np.array([fences[k, v].bbox for v in volume.tolist()])  # (N, 4)
        hit = ~(
            (plo[:, 0] > bx[:, 2])
            | (plo[:, 1] > bx[:, 3])
            | (phi[:, 0] < bx[:, 0])
            | (phi[:, 1] < bx[:, 1])
        )
        near.extend((int(i), k) for i in np.flatnonzero(hit))
    out: list[PlanGeofenceCrossing] = []
    for i, k in sorted(near):
        op = operations[i]
        t = _fence_crossing(local[i], fences[k, op.operational_volume_m])
        if t is not None:
            out.append(
                PlanGeofenceCrossing(operation_id=op.id, geofence_id=geofences[k].id, entry_t_s=t)
            )
    return out


class FiledPlans:
    """The filed plans of an airspace, indexed (:class:`~.plan_index.PlanIndex`) so that ONE
    plan is checked against all of them without re-checking the others: the call a filing
    operator waits for. Keep it in step with the airspace: ``add`` on filing and on each new
    plan version, ``remove`` when an operation ends."""

    def __init__(self, frame: LocalFrame, config: MonitoringConfig, *, step_s: float = 1.0) -> None:
        self.frame = frame
        self.config = config
        self.step_s = step_s
        self._index = PlanIndex(window_s_of(config, step_s))
        self._filed: dict[object, tuple[Operation, FloatArray]] = {}
        self._seq = 0

    def __len__(self) -> int:
        return len(self._index)

    def __contains__(self, op_id: object) -> bool:
        return op_id in self._index

    def _grow(self, volume_m: float) -> FloatArray:
        out: FloatArray = growth_m(self.config, np.array([volume_m]))[0]
        return out

    def add(self, op: Operation) -> None:
        """File (or re-file with its current plan) ``op``."""
        local = plan_local(op.plan, self.frame)
        self._filed[op.id] = (op, local)
        self._index.add(op.id, local, self._grow(op.operational_volume_m))

    def add_many(self, ops: Sequence[Operation]) -> None:
        """File many operations at once (one vectorised pass). Operations sharing an id are
        kept apart (each is checked, as in a list of operations)."""
        local = plans_local([op.plan for op in ops], self.frame)
        keys: list[object] = []
        for op, pts in zip(ops, local, strict=True):
            key: object = op.id if op.id not in self._filed else (op.id, self._seq)
            self._seq += 1
            self._filed[key] = (op, pts)
            keys.append(key)
        volume = np.array([op.operational_volume_m for op in ops], np.float64)
        self._index.add_many(keys, local, growth_m(self.config, volume))

    def remove(self, op_id: object) -> bool:
        """Withdraw ``op_id``'s plan; False if it was not filed."""
        self._filed.pop(op_id, None)
        return self._index.remove(op_id)

    def check(self, plan: FlightPlan, op: Operation) -> list[PlanConflict]:
        """Conflicts of ``plan`` (flown by ``op``) with every filed plan except ``op``'s own,
        in filing order. ``PlanConflict.a`` is ``op.id``."""
        pa = plan_local(plan, self.frame)
        cfg = self.config
        pairs: list[_Pair] = []
        for key in self._index.candidates(pa, self._grow(op.operational_volume_m)):
            other, pb = self._filed[key]
            if other.id == op.id:
                continue
            mh, mv = cfg.effective_minima(op.operational_volume_m, other.operational_volume_m)
            pairs.append(_Pair(pa, pb, op.id, other.id, mh, mv))
        found = _pair_conflicts(pairs, spherical=cfg.spherical, step_s=self.step_s)
        return [c for c in found if c is not None]
