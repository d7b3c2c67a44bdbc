"""Tactical Deconfliction: alternatives, each with cost and riskiness, for EM to choose from.

Two families (paper §4.5):

- multi-UAS loss of separation: charged cords (:mod:`.cords`) in several scenarios: a joint
  vertical and a joint lateral repulsion where every mobile UAS moves in inverse proportion to
  its priority (neighbours that the deformation pushes into are part of the problem, which
  resolves chains), and per involved UAS a single-mover go up / go down / go left / go right;
  plus a delay and a speed change found by search, and keep-plan (cost 0) for every UAS;
- single UAS: A* on a visibility graph of inflated geofences (:mod:`.astar`): reroute around a
  crossing, escape from inside, direct to goal, back to plan, next waypoint, return home,
  nearest reachable landing site.

Every new plan starts at the UAS now, has times from its cruise speed and climb rate (never
faster than it asked for originally), and is verified by the Monitoring core
(``plan_vs_geofences`` and ``plan_vs_plans`` against every operation outside the problem)
before it is returned; dropped candidates are listed in :attr:`TacticalDeconfliction.dropped`.
Compatibility between alternatives of UAS in the same problem is checked with the same
Monitoring function by :meth:`TacticalDeconfliction.compatible` during EM's joint selection.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from shapely.geometry import LineString, Point

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction.astar import VisibilityPlanner
from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.geometry import (
    LocalFence,
    LocalPlan,
    fence_to_local,
    local_to_plans,
    max_speeds,
    merged_obstacles,
    plan_to_local,
    relevant_fences,
    separation_screen,
)
from gcs_utm.core.deconfliction.scoring import Neighbour, Reference, Score, reference, score_many
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_geofences, plan_vs_plans
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FlightPlan,
    FloatArray,
    Geofence,
    Maneuver,
    Operation,
    OperationId,
    OperationState,
    Threat,
)

_INACTIVE = (OperationState.LANDED, OperationState.ENDED)
_ABANDON = (Maneuver.RETURN_HOME, Maneuver.LANDING_SITE)


@dataclass(frozen=True, slots=True, kw_only=True)
class Dropped:
    """A candidate that was generated but not offered, and why."""

    operation_id: OperationId
    maneuver: Maneuver
    reason: str


@dataclass(frozen=True, slots=True, eq=False)
class _Screen:
    """Another plan sampled on the timing search's grid (one array per coordinate), its
    validity there and the pair's minima."""

    e: FloatArray
    n: FloatArray
    z: FloatArray
    ok: npt.NDArray[np.bool_]
    h_min_m: float
    v_min_m: float


@dataclass(slots=True, kw_only=True, eq=False)
class _Candidate:
    """A new plan waiting for Monitoring's verification and for its score (see
    :meth:`TacticalDeconfliction._flush`); ``keep`` marks the filed plan itself (no
    conversion, verified against every geofence, cost 0). The alternative, if any, is
    appended to ``dest``."""

    op: Operation
    maneuver: Maneuver
    new: LocalPlan
    old: LocalPlan
    geofences: Sequence[Geofence]
    fences: Sequence[LocalFence]
    outsiders: Sequence[Operation]
    lowest_priority: int
    detail: str
    dest: list[Alternative]
    verify_from: int = 0
    keep: bool = False


class TacticalDeconfliction:
    """Generates verified alternatives; pure apart from the :attr:`dropped` diagnostics of
    the last call."""

    def __init__(
        self, frame: LocalFrame, config: DeconflictionConfig, monitoring: MonitoringConfig
    ) -> None:
        self.frame = frame
        self.config = config
        self.monitoring = monitoring
        self.dropped: list[Dropped] = []
        # Candidates and drops of the current call, in the order they were made (_flush).
        self._queue: list[_Candidate | Dropped] = []
        # Local conversions of the plans in the current snapshot, keyed by object identity
        # (the plan is kept in the value so its id cannot be reused while cached).
        self._local: dict[int, tuple[FlightPlan, LocalPlan]] = {}
        self._speeds: dict[int, tuple[FlightPlan, tuple[float, float]]] = {}

    def _lp(self, plan: FlightPlan) -> LocalPlan:
        hit = self._local.get(id(plan))
        if hit is None or hit[0] is not plan:
            if len(self._local) > 4096:
                self._local.clear()
            hit = (plan, plan_to_local(plan, self.frame))
            self._local[id(plan)] = hit
        return hit[1]

    def _max_speeds(self, plan: FlightPlan) -> tuple[float, float]:
        hit = self._speeds.get(id(plan))
        if hit is None or hit[0] is not plan:
            if len(self._speeds) > 4096:
                self._speeds.clear()
            hit = (plan, max_speeds(self._lp(plan)))
            self._speeds[id(plan)] = hit
        return hit[1]

    # ---- helpers on the snapshot -------------------------------------------------------------
    def _others(
        self, snapshot: AirspaceSnapshot, exclude: Collection[OperationId]
    ) -> list[Operation]:
        return [
            op
            for op in snapshot.operations.values()
            if op.id not in exclude
            and op.state not in _INACTIVE
            and op.plan.end_t_s >= snapshot.t_s
        ]

    def current_xyz(self, op: Operation, snapshot: AirspaceSnapshot) -> FloatArray:
        """Where the UAS is now: its track if tracked, else its plan at the snapshot time."""
        for tr in snapshot.tracks.values():
            if tr.operation_id == op.id and not tr.stale:
                e, n = self.frame.point_to_local(tr.lat_deg, tr.lon_deg)
                return np.array([e, n, tr.alt_amsl_m])
        return self._lp(op.plan).position_at(snapshot.t_s)

    def _alt_limits(self, op: Operation) -> tuple[float, float]:
        lo = op.min_alt_amsl_m if op.min_alt_amsl_m is not None else self.config.min_alt_amsl_m
        hi = op.max_alt_amsl_m if op.max_alt_amsl_m is not None else self.config.max_alt_amsl_m
        return lo, hi

    def _mobility(self, op: Operation) -> float:
        if op.priority >= self.config.immovable_priority:
            return 0.0
        return 1.0 / max(op.priority, 1)

    def verify(
        self,
        plan: FlightPlan,
        op: Operation,
        others: Sequence[Operation],
        geofences: Sequence[Geofence],
    ) -> list[str]:
        """What Monitoring would flag on ``plan`` (empty list = clean). With nothing to check
        against, Monitoring is not asked (it would convert the plan and find nothing)."""
        flags: list[str] = []
        if geofences:
            flags += [
                f"geofence {c.geofence_id} at t={c.entry_t_s:.1f}"
                for c in plan_vs_geofences(plan, op, geofences, self.frame, self.monitoring)
            ]
        if any(o.id != op.id for o in others):
            flags += [
                f"separation with {c.b} at t={c.first_loss_t_s:.1f} ({c.min_distance_m:.1f} m)"
                for c in plan_vs_plans(plan, op, others, self.frame, self.monitoring)
            ]
        return flags

    def compatible(self, a: Alternative, b: Alternative, snapshot: AirspaceSnapshot) -> bool:
        """True when the plans of two alternatives (of different UAS) keep separation, as
        Monitoring checks it. An alternative without a plan (a command) is compatible."""
        if a.plan is None or b.plan is None:
            return True
        op_a = snapshot.operations[a.operation_id]
        op_b = snapshot.operations[b.operation_id]
        # Sound shortcuts either way (see separation_screen); only an undecided pair goes to
        # Monitoring's exact closest-approach check.
        h, v = self.monitoring.effective_minima(
            op_a.operational_volume_m, op_b.operational_volume_m
        )
        broken, clear = separation_screen(
            self._lp(a.plan),
            self._lp(b.plan),
            h,
            v,
            spherical=self.monitoring.spherical,
            speeds_a=self._max_speeds(a.plan),
            speeds_b=self._max_speeds(b.plan),
        )
        if broken:
            return False
        if clear:
            return True
        # Only now the operation with the alternative's plan (the screen needs none).
        op_b = replace(op_b, plan=b.plan)
        return not plan_vs_plans(a.plan, op_a, [op_b], self.frame, self.monitoring)

    def _reference(
        self, op: Operation, old: LocalPlan, neighbours: Sequence[Operation]
    ) -> Reference:
        nbs = []
        for o in neighbours:
            h, v = self.monitoring.effective_minima(op.operational_volume_m, o.operational_volume_m)
            nbs.append(Neighbour(plan=self._lp(o.plan), h_min_m=h, v_min_m=v))
        return reference(old, self._lp(op.plan), op.operational_volume_m, nbs)

    def _finish(
        self,
        op: Operation,
        maneuver: Maneuver,
        new: LocalPlan,
        old: LocalPlan,
        *,
        geofences: Sequence[Geofence],
        fences: Sequence[LocalFence],
        outsiders: Sequence[Operation],
        lowest_priority: int,
        detail: str,
        dest: list[Alternative],
        verify_from: int = 0,
    ) -> None:
        """Queue ``new`` for verification by Monitoring and scoring (:meth:`_flush`), its
        alternative for ``dest``. ``verify_from`` skips leading waypoints (an escape leg that
        starts inside a fence)."""
        self._queue.append(
            _Candidate(
                op=op,
                maneuver=maneuver,
                new=new,
                old=old,
                geofences=geofences,
                fences=fences,
                outsiders=outsiders,
                lowest_priority=lowest_priority,
                detail=detail,
                dest=dest,
                verify_from=verify_from,
            )
        )

    def _drop(self, op_id: OperationId, maneuver: Maneuver, reason: str) -> None:
        self._queue.append(Dropped(operation_id=op_id, maneuver=maneuver, reason=reason))

    def _flush(self, now: float) -> None:
        """Turn the queued candidates into alternatives: all new plans converted to WGS84 at
        once, each verified by Monitoring (in queue order, so :attr:`dropped` lists drops in
        the order the candidates were made), the survivors of one UAS scored together against
        one prepared reference (:func:`score_many`), then appended to their lists in queue
        order."""
        queue, self._queue = self._queue, []
        moved = [c for c in queue if isinstance(c, _Candidate) and not c.keep]
        converted = local_to_plans(
            [c.new for c in moved],
            [c.op.plan for c in moved],
            self.frame,
            created_t_s=now,
            reasons=[f"TD {c.maneuver.value}" for c in moved],
        )
        plans = {id(c): p for c, p in zip(moved, converted, strict=True)}
        passed: list[tuple[_Candidate, FlightPlan, list[bool]]] = []
        for c in queue:
            if isinstance(c, Dropped):
                self.dropped.append(c)
                continue
            flags, plan, applies = self._check(c, plans.get(id(c)))
            if flags:
                self.dropped.append(
                    Dropped(operation_id=c.op.id, maneuver=c.maneuver, reason="; ".join(flags))
                )
            else:
                passed.append((c, plan, applies))
        # Candidates of one UAS against the same remaining plan, neighbours, priority floor
        # and fence list share a reference and are scored in one pass.
        groups: dict[tuple[object, ...], list[int]] = {}
        for k, (c, _, _) in enumerate(passed):
            key = (
                c.op.id,
                id(c.old),
                id(c.fences),
                c.lowest_priority,
                *(o.id for o in c.outsiders),
            )
            groups.setdefault(key, []).append(k)
        scores: list[Score | None] = [None] * len(passed)
        cfg = self.config
        for idx in groups.values():
            c0 = passed[idx[0]][0]
            op = c0.op
            levels = max(0, op.priority - c0.lowest_priority)
            got = score_many(
                [passed[k][0].new for k in idx],
                self._reference(op, c0.old, c0.outsiders),
                fences=c0.fences,
                applies=[np.array(passed[k][2], dtype=bool) for k in idx],
                priority_weight=1.0 + cfg.priority_cost_weight * levels,
                priority_levels=levels,
                abandons=[passed[k][0].maneuver in _ABANDON for k in idx],
                spherical=self.monitoring.spherical,
                config=cfg,
            )
            for k, sc in zip(idx, got, strict=True):
                scores[k] = sc
        for (c, plan, _), got_sc in zip(passed, scores, strict=True):
            assert got_sc is not None
            sc = got_sc
            terms = ", ".join(f"{k}={v}" for k, v in sc.as_dict().items())
            c.dest.append(
                Alternative(
                    operation_id=c.op.id,
                    maneuver=c.maneuver,
                    plan=plan,
                    cost=0.0 if c.keep else sc.cost,
                    risk=sc.risk,
                    detail=f"{c.detail}; {terms}",
                    extra_length_m=sc.extra_distance_m,
                    extra_time_s=sc.extra_time_s,
                    separation_ratio=ratio
                    if math.isfinite(ratio := sc.min_separation_ratio)
                    else None,
                    fence_distance_m=fence
                    if math.isfinite(fence := sc.min_fence_distance_m)
                    else None,
                )
            )

    def _check(
        self, c: _Candidate, plan: FlightPlan | None
    ) -> tuple[list[str], FlightPlan, list[bool]]:
        """Monitoring's flags on a candidate's plan, the plan, and which of its fences the
        score counts."""
        op = c.op
        if c.keep:
            flags = self.verify(op.plan, op, c.outsiders, c.geofences)
            return flags, op.plan, [True] * len(c.fences)
        assert plan is not None
        self._local[id(plan)] = (plan, c.new)  # its local form, without a second conversion
        checked = plan
        if c.verify_from > 0:
            checked = replace(plan, waypoints=plan.waypoints[c.verify_from :])
        # Monitoring's check is exact but costs a buffer per fence: hand it only the fences
        # whose box comes within the OV radius of the new plan's box (the others cannot be
        # crossed), and score only those within the proximity range.
        ov = op.operational_volume_m
        near_g = [
            g
            for g, near in zip(c.geofences, _near(c.fences, c.new, ov + 1.0), strict=True)
            if near and g.applies_to(op.id)
        ]
        flags = self.verify(checked, op, c.outsiders, near_g)
        if flags:
            return flags, plan, []
        reach = ov * self.config.risk_proximity_factor + 1.0
        applies = [
            near and g.applies_to(op.id)
            for g, near in zip(c.geofences, _near(c.fences, c.new, reach), strict=True)
        ]
        return flags, plan, applies

    def _local_fences(self, geofences: Sequence[Geofence]) -> list[LocalFence]:
        return [fence_to_local(g, self.frame) for g in geofences]

    # ---- multi-UAS --------------------------------------------------------------------------
    def resolve_loss_of_separation(
        self, threat: Threat, snapshot: AirspaceSnapshot
    ) -> dict[OperationId, list[Alternative]]:
        """Alternatives per UAS of the conflict and of the neighbours drawn into it. Every UAS
        gets ``KEEP_PLAN`` (if Monitoring does not flag its plan against outsiders) so that
        EM's joint selection can leave the higher-priority UAS alone."""
        self.dropped = []
        self._queue = []
        now = snapshot.t_s
        cfg = self.config
        involved = [snapshot.operations[i] for i in threat.uas_ids if i in snapshot.operations]
        if not involved:
            return {}
        local = {op.id: self._lp(op.plan).after(now) for op in involved}
        end = min(now + cfg.horizon_s, max(float(lp.t[-1]) for lp in local.values()))
        steps = max(2, math.ceil((end - now) / cfg.cord_dt_s) + 1)
        grid: FloatArray = now + np.arange(steps, dtype=np.float64) * cfg.cord_dt_s
        members = list(involved) + self._neighbours(involved, snapshot, grid)
        for op in members:
            local.setdefault(op.id, self._lp(op.plan).after(now))
        ids = {op.id for op in members}
        outsiders = self._others(snapshot, ids)
        geofences = snapshot.geofences
        fences = self._local_fences(geofences)
        u = len(members)
        minima = np.zeros((u, u, 2))
        for i, a in enumerate(members):
            for j, b in enumerate(members):
                minima[i, j] = self.monitoring.effective_minima(
                    a.operational_volume_m, b.operational_volume_m
                )
        lowest = min(op.priority for op in members)
        out: dict[OperationId, list[Alternative]] = {op.id: [] for op in members}
        for op in members:
            # Keeping the plan moves nothing: no priority price (the score's cost is then 0).
            self._queue.append(
                _Candidate(
                    op=op,
                    maneuver=Maneuver.KEEP_PLAN,
                    new=local[op.id],
                    old=local[op.id],
                    geofences=geofences,
                    fences=fences,
                    outsiders=outsiders,
                    lowest_priority=op.priority,
                    detail="keep the current plan",
                    dest=out[op.id],
                    keep=True,
                )
            )

        def run(axes: list[str], signs: list[int], mobile: list[bool], label: str) -> None:
            cords = []
            for k, op in enumerate(members):
                lo, hi = self._alt_limits(op)
                vertical = axes[k] == cd.AXIS_VERTICAL
                slope = (
                    op.max_climb_rate_mps * cfg.climb_fraction * cfg.cord_dt_s
                    if vertical
                    else cd.lateral_slope(
                        op.cruise_speed_mps, cfg.cord_dt_s, cfg.max_lateral_angle_deg
                    )
                )
                cords.append(
                    cd.Cord(
                        plan=local[op.id],
                        axis=axes[k] if mobile[k] else cd.AXIS_NONE,
                        sign=signs[k],
                        mobility=self._mobility(op) if mobile[k] else 0.0,
                        slope_m_per_step=slope,
                        max_offset_m=cfg.max_vertical_offset_m
                        if vertical
                        else cfg.max_lateral_offset_m,
                        min_alt_amsl_m=lo,
                        max_alt_amsl_m=hi,
                    )
                )
            res = cd.resolve(
                cords,
                grid,
                minima,
                spherical=self.monitoring.spherical,
                margin_fraction=cfg.separation_margin_fraction,
                max_iterations=cfg.max_iterations,
                problem=problem,
            )
            if res is None:
                for k, op in enumerate(members):
                    if mobile[k] and op in involved:
                        self._drop(op.id, Maneuver.KEEP_PLAN, f"{label}: no convergence")
                return
            for k, op in enumerate(members):
                dk = res.displacement_m[k]
                if cords[k].axis == cd.AXIS_NONE or float(dk.max()) < 0.5:
                    continue
                sign = res.signs[k]
                man = _maneuver(cords[k].axis, sign)
                new = self._deformed(op, local[op.id], grid, dk, cords[k].axis, sign)
                self._finish(
                    op,
                    man,
                    new,
                    local[op.id],
                    geofences=geofences,
                    fences=fences,
                    outsiders=outsiders,
                    lowest_priority=lowest,
                    detail=f"{label}: {man.value} up to {float(dk.max()):.0f} m",
                    dest=out[op.id],
                )

        # Axes, signs and mobility aside, every scenario works on the same cords.
        problem = cd.prepare(
            [local[op.id] for op in members],
            grid,
            minima,
            spherical=self.monitoring.spherical,
            margin_fraction=cfg.separation_margin_fraction,
        )
        mobile_all = [self._mobility(op) > 0 for op in members]
        run([cd.AXIS_VERTICAL] * u, [0] * u, mobile_all, "joint vertical repulsion")
        run([cd.AXIS_LATERAL] * u, [0] * u, mobile_all, "joint lateral repulsion")
        for k, op in enumerate(members):
            if op not in involved or not mobile_all[k]:
                continue
            only = [j == k for j in range(u)]
            for axis, sign in (
                (cd.AXIS_VERTICAL, 1),
                (cd.AXIS_VERTICAL, -1),
                (cd.AXIS_LATERAL, 1),
                (cd.AXIS_LATERAL, -1),
            ):
                signs = [sign if j == k else 0 for j in range(u)]
                run([axis] * u, signs, only, f"{op.id} alone")
            rigid = [o for o in members if o.id != op.id]
            self._timing(
                op, local[op.id], snapshot, geofences, fences, outsiders, rigid, lowest, out[op.id]
            )
        self._flush(now)
        return {k: _dedupe(v) for k, v in out.items() if v or k in threat.uas_ids}

    def _neighbours(
        self, involved: Sequence[Operation], snapshot: AirspaceSnapshot, grid: FloatArray
    ) -> list[Operation]:
        """Operations whose plans come within 3x the minima of an involved plan inside the
        horizon: the ones a deformation can push into (nearest first, at most
        ``max_neighbours``)."""
        ids = {op.id for op in involved}
        pos = [self._lp(op.plan).sample(grid) for op in involved]
        found: list[tuple[float, Operation]] = []
        for other in self._others(snapshot, ids):
            p, ok = self._lp(other.plan).sample(grid)
            best = math.inf
            for op, (q, ok2) in zip(involved, pos, strict=True):
                m = ok & ok2
                if not m.any():
                    continue
                h, v = self.monitoring.effective_minima(
                    op.operational_volume_m, other.operational_volume_m
                )
                dh = np.hypot(p[m, 0] - q[m, 0], p[m, 1] - q[m, 1]) / h
                dv = np.abs(p[m, 2] - q[m, 2]) / v
                best = min(best, float(np.maximum(dh, dv).min()))
            if best < 3.0:
                found.append((best, other))
        found.sort(key=lambda x: x[0])
        return [op for _, op in found[: self.config.max_neighbours]]

    def _deformed(  # noqa: PLR0917 - private helper, called positionally
        self,
        op: Operation,
        lp: LocalPlan,
        grid: FloatArray,
        d: FloatArray,
        axis: str,
        sign: int,
    ) -> LocalPlan:
        """The plan through the displaced cord, re-timed so that no segment is faster than
        allowed (its original pace, or the cruise speed, times max_speed_factor).

        The displacement is piecewise linear on the grid (an envelope of cones, capped), so
        the new plan needs points only at the filed waypoints and at the grid times where the
        displacement's slope changes: between those it is exactly the cord."""
        # (plain slicing: np.diff does the same subtractions, with call overhead)
        d1 = d[1:] - d[:-1]
        kinks = grid[1:-1][np.abs(d1[1:] - d1[:-1]) > 1e-9]
        inside = (kinks >= lp.t[0]) & (kinks <= lp.t[-1])
        # np.union1d without its wrappers: sorted, duplicates removed.
        times = np.concatenate((kinks[inside], lp.t))
        times.sort()
        if times.shape[0] > 1:
            times = times[np.concatenate(([True], times[1:] != times[:-1]))]
        # One array per coordinate (the same arithmetic as on (N, 3) rows, without the
        # strided column reads).
        if len(lp) == 1:
            be = np.full(times.shape[0], lp.e[0])
            bn = np.full(times.shape[0], lp.n[0])
            bz = np.full(times.shape[0], lp.z[0])
        else:
            be = np.interp(times, lp.t, lp.e)
            bn = np.interp(times, lp.t, lp.n)
            bz = np.interp(times, lp.t, lp.z)
        disp = sign * np.interp(times, grid, d)
        xe, xn, xz = be, bn, bz
        if axis == cd.AXIS_VERTICAL:
            xz = bz + disp
        else:
            nx, ny = cd.left_normals_en(be, bn)
            xe = be + disp * nx
            xn = bn + disp * ny
        # Original pace between the kept times, from the undeformed plan.
        dt = times[1:] - times[:-1]
        safe_dt = np.maximum(dt, 1e-9)
        f = self.config.max_speed_factor
        speed = (
            np.maximum(op.cruise_speed_mps, np.hypot(be[1:] - be[:-1], bn[1:] - bn[:-1]) / safe_dt)
            * f
        )
        climb = np.maximum(op.max_climb_rate_mps, np.abs(bz[1:] - bz[:-1]) / safe_dt) * f
        need = np.maximum(
            dt,
            np.maximum(
                np.hypot(xe[1:] - xe[:-1], xn[1:] - xn[:-1]) / speed,
                np.abs(xz[1:] - xz[:-1]) / climb,
            ),
        )
        t = np.empty(len(times))
        t[0] = times[0]
        np.cumsum(need, out=t[1:])
        t[1:] += times[0]
        off_e = xe[-1] - lp.e[-1]
        off_n = xn[-1] - lp.n[-1]
        off_z = xz[-1] - lp.z[-1]
        if max(abs(off_e), abs(off_n), abs(off_z)) > 1e-3:
            # The plan ended before the cord could ramp back: fly back to the filed final
            # waypoint (cruise speed, climb rate) so the alternative keeps the destination.
            dt_back = max(
                float(np.hypot(off_e, off_n)) / op.cruise_speed_mps,
                abs(float(off_z)) / op.max_climb_rate_mps,
            )
            xe = np.append(xe, lp.e[-1])
            xn = np.append(xn, lp.n[-1])
            xz = np.append(xz, lp.z[-1])
            t = np.append(t, t[-1] + dt_back)
        return LocalPlan(xe, xn, xz, t)

    def _timing(  # noqa: PLR0917 - private helper, called positionally
        self,
        op: Operation,
        lp: LocalPlan,
        snapshot: AirspaceSnapshot,
        geofences: Sequence[Geofence],
        fences: Sequence[LocalFence],
        outsiders: Sequence[Operation],
        rigid: Sequence[Operation],
        lowest: int,
        dest: list[Alternative],
    ) -> None:
        """The smallest delay (hold at the current point, then the same plan later) and the
        mildest slow-down that separate ``op`` from every other plan, if any, queued for
        ``dest``."""
        now = snapshot.t_s
        cfg = self.config
        others = list(rigid) + list(outsiders)
        slowest = min([f for f in cfg.slowdown_factors if 0.0 < f < 1.0] or [1.0])
        span = float(lp.t[-1] - now)
        grid_t = np.arange(now, now + max(span / slowest, span + cfg.max_delay_s) + 1.0, 1.0)
        screens = []
        for o in others:
            q, ok = self._lp(o.plan).sample(grid_t)
            h, v = self.monitoring.effective_minima(op.operational_volume_m, o.operational_volume_m)
            screens.append(_Screen(q[:, 0].copy(), q[:, 1].copy(), q[:, 2].copy(), ok, h, v))
        delay = self._first_clear_delay(lp, now, grid_t, screens)
        if delay is not None:
            t = np.concatenate([[now, now + delay], lp.t[1:] + delay])
            e = np.concatenate([[lp.e[0]], lp.e])
            n = np.concatenate([[lp.n[0]], lp.n])
            z = np.concatenate([[lp.z[0]], lp.z])
            self._finish(
                op,
                Maneuver.DELAY,
                LocalPlan(e, n, z, t),
                lp,
                geofences=geofences,
                fences=fences,
                outsiders=others,
                lowest_priority=lowest,
                detail=f"hold {delay:.0f} s here, then the plan",
                dest=dest,
            )
        for factor in cfg.slowdown_factors:
            if not 0.0 < factor < 1.0:
                continue
            cand = LocalPlan(lp.e, lp.n, lp.z, now + (lp.t - now) / factor)
            if self._clear(cand, grid_t, screens):
                self._finish(
                    op,
                    Maneuver.SPEED_CHANGE,
                    cand,
                    lp,
                    geofences=geofences,
                    fences=fences,
                    outsiders=others,
                    lowest_priority=lowest,
                    detail=f"fly the plan at {factor:.0%} of its speed",
                    dest=dest,
                )
                break

    def _first_clear_delay(
        self,
        lp: LocalPlan,
        now: float,
        grid_t: FloatArray,
        screens: Sequence[_Screen],
    ) -> float | None:
        """The smallest delay step after which holding here and then flying the plan keeps
        (1 + margin) times the minima from every screened plan; all delays at once."""
        cfg = self.config
        steps = int(cfg.max_delay_s // cfg.delay_step_s)
        if steps < 1:
            return None
        delays = cfg.delay_step_s * np.arange(1, steps + 1, dtype=np.float64)
        tt = np.maximum(grid_t[None, :] - delays[:, None], now)  # (D, T): plan time flown
        valid = tt <= lp.t[-1]
        # Positions at the plan times flown, one (D, T) array per coordinate. When every
        # plan time is itself a grid time (a delay that is a whole number of grid steps,
        # checked value by value), they are the plan sampled once on the grid, gathered;
        # otherwise interpolated.
        shift = np.rint(delays / (grid_t[1] - grid_t[0]) if grid_t.shape[0] > 1 else delays)
        idx = np.maximum(np.arange(grid_t.shape[0])[None, :] - shift.astype(np.intp)[:, None], 0)
        if np.array_equal(grid_t[idx], tt):
            pe, pn, pz = (np.interp(grid_t, lp.t, c)[idx] for c in (lp.e, lp.n, lp.z))
        else:
            pe, pn, pz = (np.interp(tt, lp.t, c) for c in (lp.e, lp.n, lp.z))
        scale = 1.0 + cfg.separation_margin_fraction
        clear = np.ones(delays.shape[0], dtype=bool)
        for sc in screens:
            m = valid & sc.ok[None, :]
            dh = np.hypot(pe - sc.e[None, :], pn - sc.n[None, :])
            dv = np.abs(pz - sc.z[None, :])
            if self.monitoring.spherical:
                ratio = np.hypot(dh, dv) / sc.h_min_m
            else:
                ratio = np.maximum(dh / sc.h_min_m, dv / sc.v_min_m)
            clear &= ~((ratio < scale) & m).any(axis=1)
        idx_clear = np.flatnonzero(clear)
        return float(delays[idx_clear[0]]) if idx_clear.size else None

    def _clear(
        self,
        cand: LocalPlan,
        grid_t: FloatArray,
        screens: Sequence[_Screen],
    ) -> bool:
        """Fast screen of a timing candidate on a 1 s grid (Monitoring verifies the one that
        passes): every other plan at least (1 + margin) times the pair's minima away."""
        pos, mine = cand.sample(grid_t)
        scale = 1.0 + self.config.separation_margin_fraction
        for sc in screens:
            m = sc.ok & mine
            if not m.any():
                continue
            dh = np.hypot(pos[m, 0] - sc.e[m], pos[m, 1] - sc.n[m])
            dv = np.abs(pos[m, 2] - sc.z[m])
            if self.monitoring.spherical:
                ratio = np.hypot(dh, dv) / sc.h_min_m
            else:
                ratio = np.maximum(dh / sc.h_min_m, dv / sc.v_min_m)
            if float(ratio.min()) < scale:
                return False
        return True

    # ---- intruder ---------------------------------------------------------------------------
    def intruder_plan(self, threat: Threat, snapshot: AirspaceSnapshot) -> LocalPlan | None:
        """The intruder's predicted path: its row of the snapshot's prediction, else its track
        extrapolated at constant velocity over the horizon."""
        tid = threat.intruder_id
        if tid is None:
            return None
        pred = snapshot.prediction
        if pred is not None and tid in pred.track_ids:
            pts = pred.points[pred.track_ids.index(tid)]
            return LocalPlan(pts[:, 0].copy(), pts[:, 1].copy(), pts[:, 2].copy(), pts[:, 3].copy())
        tr = snapshot.tracks.get(tid)
        if tr is None:
            return None
        h = self.config.horizon_s
        ve, vn, vu = tr.vel_enu_mps
        return LocalPlan(
            np.array([tr.east_m, tr.east_m + ve * h]),
            np.array([tr.north_m, tr.north_m + vn * h]),
            np.array([tr.alt_amsl_m, tr.alt_amsl_m + vu * h]),
            np.array([tr.t_s, tr.t_s + h]),
        )

    def resolve_intruder(
        self, threat: Threat, operation_id: OperationId, snapshot: AirspaceSnapshot
    ) -> list[Alternative]:
        """Vertical avoidance of a non-cooperative intruder: the UAS's cord alone climbs or
        descends (the intruder is a rigid cord) until the intruder minima hold."""
        self.dropped = []
        self._queue = []
        op = snapshot.operations.get(operation_id)
        intruder = self.intruder_plan(threat, snapshot)
        if op is None or intruder is None:
            return []
        now = snapshot.t_s
        cfg = self.config
        lp = self._lp(op.plan).after(now)
        end = min(now + cfg.horizon_s, float(lp.t[-1]))
        steps = max(2, math.ceil((end - now) / cfg.cord_dt_s) + 1)
        grid: FloatArray = now + np.arange(steps, dtype=np.float64) * cfg.cord_dt_s
        mon = self.monitoring
        h_min = max(mon.intruder_horizontal_m, op.operational_volume_m)
        v_min = max(mon.intruder_vertical_m, op.operational_volume_m)
        minima = np.array([[[h_min, v_min]] * 2] * 2)
        lo, hi = self._alt_limits(op)
        outsiders = self._others(snapshot, {op.id})
        fences = self._local_fences(snapshot.geofences)
        out: list[Alternative] = []
        for sign in (1, -1):
            cords = [
                cd.Cord(
                    plan=lp,
                    axis=cd.AXIS_VERTICAL,
                    sign=sign,
                    mobility=1.0,
                    slope_m_per_step=op.max_climb_rate_mps * cfg.climb_fraction * cfg.cord_dt_s,
                    max_offset_m=cfg.max_vertical_offset_m,
                    min_alt_amsl_m=lo,
                    max_alt_amsl_m=hi,
                ),
                cd.Cord(
                    plan=intruder,
                    axis=cd.AXIS_NONE,
                    sign=0,
                    mobility=0.0,
                    slope_m_per_step=0.0,
                    max_offset_m=0.0,
                    min_alt_amsl_m=lo,
                    max_alt_amsl_m=hi,
                ),
            ]
            res = cd.resolve(
                cords,
                grid,
                minima,
                spherical=False,
                margin_fraction=cfg.separation_margin_fraction,
                max_iterations=cfg.max_iterations,
            )
            man = Maneuver.GO_UP if sign > 0 else Maneuver.GO_DOWN
            if res is None:
                self._drop(op.id, man, "no convergence")
                continue
            dk = res.displacement_m[0]
            new = self._deformed(op, lp, grid, dk, cd.AXIS_VERTICAL, sign)
            self._finish(
                op,
                man,
                new,
                lp,
                geofences=snapshot.geofences,
                fences=fences,
                outsiders=outsiders,
                lowest_priority=op.priority,
                detail=f"vertical avoidance of intruder {threat.intruder_id}: "
                f"{man.value} {float(dk.max()):.0f} m",
                dest=out,
            )
        self._flush(now)
        return out

    # ---- single UAS -------------------------------------------------------------------------
    def resolve_single(
        self,
        threat: Threat,
        operation_id: OperationId,
        snapshot: AirspaceSnapshot,
        maneuvers: Collection[Maneuver] | None = None,
        extra_geofences: Sequence[Geofence] = (),
    ) -> list[Alternative]:
        """Single-UAS alternatives (A*), verified; ``maneuvers`` limits which are generated
        (None = all that apply), ``extra_geofences`` are fences not yet in the snapshot (an
        alert area EM is about to create)."""
        self.dropped = []
        self._queue = []
        op = snapshot.operations.get(operation_id)
        if op is None:
            return []
        want = set(maneuvers) if maneuvers is not None else set(Maneuver)
        now = snapshot.t_s
        cfg = self.config
        geofences = tuple(snapshot.geofences) + tuple(
            g for g in extra_geofences if g.id not in {f.id for f in snapshot.geofences}
        )
        if threat.area is not None and threat.area.id not in {g.id for g in geofences}:
            geofences += (threat.area,)
        # A dynamic geofence drawn around this UAS (jamming, link loss) does not apply to it.
        geofences = tuple(g for g in geofences if g.applies_to(op.id))
        fences = self._local_fences(geofences)
        lp = self._lp(op.plan).after(now)
        cur = self.current_xyz(op, snapshot)
        zs = np.concatenate([lp.z, [cur[2]]])
        ov = op.operational_volume_m
        active = relevant_fences(
            fences,
            now,
            max(now + cfg.horizon_s, float(lp.t[-1])),
            float(zs.min()) - ov,
            float(zs.max()) + ov,
        )
        planner = VisibilityPlanner(
            merged_obstacles(active, ov + cfg.clearance_margin_m, cfg.cylinder_sides)
        )
        outsiders = self._others(snapshot, {op.id})
        lowest = op.priority
        router = _Router(op, planner, now, cur, lp)
        out: list[Alternative] = []

        def add(man: Maneuver, route: tuple[LocalPlan, int] | None, detail: str) -> None:
            if route is None:
                self._drop(op.id, man, "no path")
                return
            new, verify_from = route
            self._finish(
                op,
                man,
                new,
                lp,
                geofences=geofences,
                fences=fences,
                outsiders=outsiders,
                lowest_priority=lowest,
                detail=detail,
                dest=out,
                verify_from=verify_from,
            )

        inside = not planner.free(cur[:2])
        if inside and Maneuver.ESCAPE in want:
            add(
                Maneuver.ESCAPE,
                router.escape(cfg.escape_distance_m),
                "leave by the closest border point, then rejoin the plan",
            )
        if not inside:
            if Maneuver.REROUTE in want:
                add(Maneuver.REROUTE, router.reroute(), "replace the crossing part of the plan")
            if Maneuver.DIRECT_TO_GOAL in want:
                add(
                    Maneuver.DIRECT_TO_GOAL,
                    router.to_point(lp.xyz()[-1]),
                    "direct to the final waypoint",
                )
            off_plan = router.distance_to_plan() > op.flight_geometry_m
            if Maneuver.BACK_TO_PLAN in want and off_plan:
                add(
                    Maneuver.BACK_TO_PLAN,
                    router.back_to_plan(),
                    "back to the closest point of the plan",
                )
            if Maneuver.NEXT_WAYPOINT in want and len(lp) > 1:
                add(Maneuver.NEXT_WAYPOINT, router.next_waypoint(), "straight to the next waypoint")
            if Maneuver.RETURN_HOME in want:
                route = router.land_at(self._home(op))
                left = self._endurance_left(op, now)
                if route is not None and left is not None and route[0].t[-1] - now > left:
                    self._drop(
                        op.id,
                        Maneuver.RETURN_HOME,
                        f"home not reachable with {left:.0f} s of endurance left",
                    )
                else:
                    add(Maneuver.RETURN_HOME, route, "return home and land")
            if Maneuver.LANDING_SITE in want and op.landing_sites:
                best = self._landing(op, router, now)
                if best is None:
                    self._drop(op.id, Maneuver.LANDING_SITE, "no landing site reachable")
                else:
                    add(Maneuver.LANDING_SITE, best[0], best[1])
        self._flush(now)
        return out

    def _home(self, op: Operation) -> FloatArray:
        if op.home is not None:
            e, n = self.frame.point_to_local(op.home.lat_deg, op.home.lon_deg)
            return np.array([e, n, op.home.alt_amsl_m])
        return np.asarray(self._lp(op.plan).xyz()[0], dtype=np.float64)

    def _endurance_left(self, op: Operation, now: float) -> float | None:
        """Usable flight time left (endurance counted from the plan start, minus the
        reserve), or None when the endurance is unknown."""
        if op.endurance_s is None:
            return None
        left = op.endurance_s - max(0.0, now - op.plan.start_t_s)
        return left * (1.0 - self.config.landing_reserve_fraction)

    def _landing(
        self, op: Operation, router: _Router, now: float
    ) -> tuple[tuple[LocalPlan, int], str] | None:
        """The landing site reached soonest that the remaining endurance covers (with the
        reserve), when the endurance is known (``Operation.endurance_s`` counted from the
        plan start)."""
        remaining = self._endurance_left(op, now)
        best: tuple[tuple[LocalPlan, int], str] | None = None
        best_t = math.inf
        for k, site in enumerate(op.landing_sites):
            e, n = self.frame.point_to_local(site.lat_deg, site.lon_deg)
            route = router.land_at(np.array([e, n, site.alt_amsl_m]))
            if route is None:
                continue
            dur = float(route[0].t[-1] - now)
            if remaining is not None and dur > remaining:
                continue
            if dur < best_t:
                best_t = dur
                best = (route, f"land at site {k} in {dur:.0f} s")
        return best


class _Router:
    """Builds 4D local plans for one UAS from A* paths: horizontal path at the cruise speed,
    altitude blended linearly along it, then the rest of the plan shifted to the arrival."""

    def __init__(
        self, op: Operation, planner: VisibilityPlanner, now: float, cur: FloatArray, lp: LocalPlan
    ) -> None:
        self.op = op
        self.planner = planner
        self.now = now
        self.cur = cur
        self.lp = lp

    def _fly(self, pts: Sequence[FloatArray], t0: float) -> LocalPlan:
        xyz = np.array([np.asarray(p, dtype=np.float64) for p in pts])
        d = np.diff(xyz, axis=0)
        need = np.maximum(
            np.hypot(d[:, 0], d[:, 1]) / self.op.cruise_speed_mps,
            np.abs(d[:, 2]) / self.op.max_climb_rate_mps,
        )
        t = np.concatenate([[t0], t0 + np.cumsum(need)])
        return LocalPlan(xyz[:, 0], xyz[:, 1], xyz[:, 2], t)

    def _path3d(self, a: FloatArray, b: FloatArray) -> list[FloatArray] | None:
        path = self.planner.path(a[:2], b[:2])
        if path is None:
            return None
        lengths = np.concatenate(
            [
                [0.0],
                np.cumsum([np.hypot(*(q - p)) for p, q in itertools.pairwise(path)]),
            ]
        )
        total = lengths[-1] if lengths[-1] > 0 else 1.0
        return [
            np.array([p[0], p[1], a[2] + (b[2] - a[2]) * s / total])
            for p, s in zip(path, lengths, strict=True)
        ]

    def _join(self, head: LocalPlan, rest_from: int) -> LocalPlan:
        """``head`` then the plan's waypoints from ``rest_from`` on, shifted in time so that
        the first of them is reached when ``head`` ends."""
        if rest_from >= len(self.lp):
            return head
        shift = float(head.t[-1]) - float(self.lp.t[rest_from])
        # ``head`` ends at waypoint rest_from, so the rest starts after it.
        sl = slice(rest_from + 1, None)
        return LocalPlan(
            np.concatenate([head.e, self.lp.e[sl]]),
            np.concatenate([head.n, self.lp.n[sl]]),
            np.concatenate([head.z, self.lp.z[sl]]),
            np.concatenate([head.t, self.lp.t[sl] + shift]),
        )

    def _route_via(
        self, start: FloatArray, t0: float, prefix: list[FloatArray], first: int
    ) -> LocalPlan | None:
        """From ``start`` through the plan's waypoints from index ``first``, replacing every
        blocked stretch by an A* path from the last free waypoint before it to the first free
        one after it."""
        pts: list[FloatArray] = [*prefix, start]
        wps = self.lp.xyz()
        free = [self.planner.free(w[:2]) for w in wps]
        i = first
        last = start
        while i < len(wps):
            if not free[i]:
                i += 1
                continue
            if self.planner.segment_free(last[:2], wps[i][:2]):
                pts.append(wps[i])
            else:
                seg = self._path3d(last, wps[i])
                if seg is None:
                    return None
                pts.extend(seg[1:])
            last = wps[i]
            i += 1
        if not free[-1]:
            return None  # the destination itself is blocked
        return self._fly(pts, t0)

    def reroute(self) -> tuple[LocalPlan, int] | None:
        plan = self._route_via(self.cur, self.now, [], 1)
        return None if plan is None else (plan, 0)

    def escape(self, extra_m: float) -> tuple[LocalPlan, int] | None:
        out2 = self.planner.exit_point(self.cur[:2], extra_m)
        out = np.array([out2[0], out2[1], self.cur[2]])
        # Rejoin at the first plan waypoint ahead that is outside every obstacle.
        plan = self._route_via(out, self.now, [self.cur], 1)
        if plan is None:
            return None
        t1 = self._fly([self.cur, out], self.now).t[-1]
        shifted = LocalPlan(
            plan.e, plan.n, plan.z, plan.t + (t1 - self.now) - (plan.t[1] - plan.t[0])
        )
        return shifted, 1

    def to_point(self, target: FloatArray) -> tuple[LocalPlan, int] | None:
        path = self._path3d(self.cur, target)
        if path is None:
            return None
        return self._fly(path, self.now), 0

    def distance_to_plan(self) -> float:
        if len(self.lp) < 2:
            return float(np.hypot(*(self.cur[:2] - self.lp.xyz()[0, :2])))
        return float(LineString(self.lp.xyz()[:, :2]).distance(Point(self.cur[0], self.cur[1])))

    def back_to_plan(self) -> tuple[LocalPlan, int] | None:
        """To the closest point of the remaining plan, then on along the plan."""
        if len(self.lp) < 2:
            return self.to_point(self.lp.xyz()[0])
        line = LineString(self.lp.xyz()[:, :2])
        s = line.project(Point(self.cur[0], self.cur[1]))
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(self.lp.e), np.diff(self.lp.n)))])
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(self.lp) - 2))
        frac = 0.0 if cum[k + 1] == cum[k] else (s - cum[k]) / (cum[k + 1] - cum[k])
        xyz = self.lp.xyz()
        q = xyz[k] + frac * (xyz[k + 1] - xyz[k])
        path = self._path3d(self.cur, q)
        if path is None:
            return None
        head = self._fly(path, self.now)
        tq = float(self.lp.t[k] + frac * (self.lp.t[k + 1] - self.lp.t[k]))
        shift = float(head.t[-1]) - tq
        sl = slice(k + 1, None)
        return (
            LocalPlan(
                np.concatenate([head.e, self.lp.e[sl]]),
                np.concatenate([head.n, self.lp.n[sl]]),
                np.concatenate([head.z, self.lp.z[sl]]),
                np.concatenate([head.t, self.lp.t[sl] + shift]),
            ),
            0,
        )

    def next_waypoint(self) -> tuple[LocalPlan, int] | None:
        target = self.lp.xyz()[1]
        path = self._path3d(self.cur, target)
        if path is None:
            return None
        return self._join(self._fly(path, self.now), 1), 0

    def land_at(self, site: FloatArray) -> tuple[LocalPlan, int] | None:
        """Cruise at the current altitude to above ``site``, then descend onto it."""
        above = np.array([site[0], site[1], self.cur[2]])
        path = self._path3d(self.cur, above)
        if path is None:
            return None
        return self._fly([*path, site], self.now), 0


def _near(fences: Sequence[LocalFence], lp: LocalPlan, margin_m: float) -> list[bool]:
    """Per fence: does its bounding box come within ``margin_m`` of the plan's bounding box."""
    e0, e1 = float(lp.e.min()) - margin_m, float(lp.e.max()) + margin_m
    n0, n1 = float(lp.n.min()) - margin_m, float(lp.n.max()) + margin_m
    out = []
    for f in fences:
        b0, b1, b2, b3 = f.shape.bounds
        out.append(b0 <= e1 and b2 >= e0 and b1 <= n1 and b3 >= n0)
    return out


def _dedupe(alts: list[Alternative]) -> list[Alternative]:
    """Drop alternatives that repeat a maneuver with the same cost and risk (two scenarios
    that deformed one UAS the same way)."""
    seen: set[tuple[Maneuver, float, float]] = set()
    out = []
    for a in alts:
        key = (a.maneuver, round(a.cost, 6), round(a.risk, 6))
        if key not in seen:
            seen.add(key)
            out.append(a)
    return out


def _maneuver(axis: str, sign: int) -> Maneuver:
    if axis == cd.AXIS_VERTICAL:
        return Maneuver.GO_UP if sign > 0 else Maneuver.GO_DOWN
    return Maneuver.GO_LEFT if sign > 0 else Maneuver.GO_RIGHT
