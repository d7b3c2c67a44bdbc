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

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import LocalFence, localise
from gcs_utm.core.monitoring.geometry import FloatArray, SegmentSeparation, segment_separation
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


def _at(pts: FloatArray, t: FloatArray) -> FloatArray:
    """Positions (len(t), 3) of a piecewise-linear 4D polyline at times t (clamped)."""
    tt = pts[:, 3]
    if len(tt) == 1:
        return np.repeat(pts[:, :3], len(t), axis=0)
    return np.column_stack([np.interp(t, tt, pts[:, k]) for k in range(3)])


@dataclass(frozen=True, slots=True)
class _Pair:
    """One pair for the exact check: both plans' local points, ids and the pair's minima."""

    pa: FloatArray
    pb: FloatArray
    ida: OperationId
    idb: OperationId
    min_h: float
    min_v: float


def _pair_samples(pair: _Pair, spherical: bool, step_s: float) -> FloatArray | None:
    """The sample times of the pair's exact check (None: the pair cannot conflict): the
    common time span cut at both plans' waypoint times and the ``step_s`` grid."""
    pa, pb = pair.pa, pair.pb
    t0 = max(pa[0, 3], pb[0, 3])
    t1 = min(pa[-1, 3], pb[-1, 3])
    if t0 > t1:
        return None
    # Cheap reject: the two plans' boxes over the common span are farther apart than the minima.
    lo_a, hi_a = pa[:, :3].min(axis=0), pa[:, :3].max(axis=0)
    lo_b, hi_b = pb[:, :3].min(axis=0), pb[:, :3].max(axis=0)
    gap = np.maximum(np.maximum(lo_a - hi_b, lo_b - hi_a), 0.0)  # m per axis
    if spherical:
        if float(np.sqrt((gap**2).sum())) >= pair.min_h:
            return None
    elif float(np.hypot(gap[0], gap[1])) >= pair.min_h or gap[2] >= pair.min_v:
        return None
    grid = np.arange(t0, t1, step_s) if step_s > 0 and t1 > t0 else np.empty(0)
    knots = np.concatenate([pa[:, 3], pb[:, 3], grid, [t0, t1]])
    t: FloatArray = np.unique(knots[(knots >= t0) & (knots <= t1)])
    if len(t) == 1:
        t = np.array([t[0], t[0]])
    return t


# Segment pairs per vectorised pass of the exact kernel: bounds memory (~20 arrays of it).
_CHUNK = 200_000


def _pair_conflicts(
    pairs: Sequence[_Pair], *, spherical: bool, step_s: float
) -> list[PlanConflict | None]:
    """The exact check of each pair (None: no conflict). Each pair's samples are taken on
    their own (:func:`_pair_samples`), then the segment kernel runs over the segments of
    many pairs at once; every figure is the one a pair alone gives (the kernel is element by
    element)."""
    out: list[PlanConflict | None] = [None] * len(pairs)
    batch: list[tuple[int, FloatArray, FloatArray, FloatArray]] = []
    size = 0
    for k, pair in enumerate(pairs):
        t = _pair_samples(pair, spherical, step_s)
        if t is None:
            continue
        batch.append((k, t, _at(pair.pa, t), _at(pair.pb, t)))
        size += len(t) - 1
        if size >= _CHUNK:
            _check_batch(batch, pairs, out, spherical)
            batch, size = [], 0
    if batch:
        _check_batch(batch, pairs, out, spherical)
    return out


def _check_batch(
    batch: list[tuple[int, FloatArray, FloatArray, FloatArray]],
    pairs: Sequence[_Pair],
    out: list[PlanConflict | None],
    spherical: bool,
) -> None:
    nseg = np.array([len(t) - 1 for _, t, _, _ in batch])
    mh = np.repeat([pairs[k].min_h for k, _, _, _ in batch], nseg)
    mv = np.repeat([pairs[k].min_v for k, _, _, _ in batch], nseg)
    seg = segment_separation(
        np.concatenate([a[:-1] for _, _, a, _ in batch]),
        np.concatenate([a[1:] for _, _, a, _ in batch]),
        np.concatenate([b[:-1] for _, _, _, b in batch]),
        np.concatenate([b[1:] for _, _, _, b in batch]),
        min_h_m=mh,
        min_v_m=mv,
        spherical=spherical,
    )
    starts = np.cumsum(nseg) - nseg
    any_loss = np.logical_or.reduceat(seg.loss, starts)
    for m in np.flatnonzero(any_loss).tolist():
        k, t, _, _ = batch[m]
        s = slice(int(starts[m]), int(starts[m] + nseg[m]))
        out[k] = _conflict(pairs[k], t, seg, s)


def _conflict(pair: _Pair, t: FloatArray, seg: SegmentSeparation, s: slice) -> PlanConflict:
    """The figures of a pair in conflict from its segments ``s`` of the kernel's result."""
    loss = seg.loss[s]
    first_loss_s = seg.first_loss_s[s]
    cpa_m = seg.cpa_m[s]
    dt = np.diff(t)
    first_s = np.where(loss, first_loss_s, 0.0)  # avoids inf * 0 on still segments
    k = int(np.argmin(np.where(loss, t[:-1] + first_s * dt, np.inf)))
    c = int(np.argmin(cpa_m))
    return PlanConflict(
        a=pair.ida,
        b=pair.idb,
        first_loss_t_s=float(t[k] + first_loss_s[k] * dt[k]),
        closest_t_s=float(t[c] + seg.cpa_s[s][c] * dt[c]),
        min_distance_m=float(cpa_m[c]),
        min_horizontal_m=float(seg.min_h_m[s].min()),
        min_vertical_m=float(seg.min_v_m[s].min()),
    )


def _pair_conflict(
    pa: FloatArray,
    pb: FloatArray,
    *,
    ida: OperationId,
    idb: OperationId,
    min_h: float,
    min_v: float,
    spherical: bool,
    step_s: float,
) -> PlanConflict | None:
    """The exact check of one pair (what the every-pair reference calls)."""
    pair = _Pair(pa, pb, ida, idb, min_h, min_v)
    return _pair_conflicts([pair], spherical=spherical, step_s=step_s)[0]


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
    ``op.operational_volume_m``, with the first such time."""
    del config  # the inflation is the operation's own volume; kept for a uniform signature
    pts = plan_local(plan, frame)
    out: list[PlanGeofenceCrossing] = []
    for g in geofences:
        if not g.applies_to(op.id):
            continue
        t = _fence_crossing(pts, localise(g, frame, op.operational_volume_m))
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
    pairs: list[_Pair] = []
    for i, j in zip((codes // n).tolist(), (codes % n).tolist(), strict=True):
        a, b = operations[i], operations[j]
        mh, mv = config.effective_minima(a.operational_volume_m, b.operational_volume_m)
        pairs.append(_Pair(local[i], local[j], a.id, b.id, mh, mv))
    found = _pair_conflicts(pairs, spherical=config.spherical, step_s=step_s)
    return [c for c in found if c is not None]


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
