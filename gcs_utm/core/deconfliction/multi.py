"""Multi-UAS loss of separation by charged cords (:mod:`.cords`; paper §4.5): a joint
vertical and a joint lateral repulsion where every mobile UAS moves in inverse proportion to
its priority (neighbours that the deformation pushes into are part of the problem, which
resolves chains), and per involved UAS a single-mover go up / go down / go left / go right;
plus a delay and a speed change (:mod:`.timing`), and keep-plan (cost 0) for every UAS.
Returns candidates for TD to verify and score. Pure."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction import loitering as lt
from gcs_utm.core.deconfliction.context import (
    Candidate,
    Context,
    Dropped,
    Problem,
    Queued,
    deform,
    vertical_slope,
)
from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.deconfliction.timing import timing_candidates
from gcs_utm.core.deconfliction.unheard import unheard
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FloatArray,
    Maneuver,
    Operation,
    OperationId,
    Threat,
)

_MANEUVER = {
    (cd.Axis.VERTICAL, 1): Maneuver.GO_UP,
    (cd.Axis.VERTICAL, -1): Maneuver.GO_DOWN,
    (cd.Axis.LATERAL, 1): Maneuver.GO_LEFT,
    (cd.Axis.LATERAL, -1): Maneuver.GO_RIGHT,
}
"""The manoeuvre a cord displaced along an axis in a sign stands for."""
_ALONE = (
    (cd.Axis.VERTICAL, 1),
    (cd.Axis.VERTICAL, -1),
    (cd.Axis.LATERAL, 1),
    (cd.Axis.LATERAL, -1),
)
"""The single-mover scenarios of an involved UAS, in order: up, down, left, right."""


class _Scenarios:
    """The cord scenarios of one problem; every candidate and drop goes to ``queue`` in the
    order it is made. ``loitering`` are the involved fixed wings on their circle and the
    neighbours whose vehicle is not heard (rigid)."""

    def __init__(self, ctx: Context, pb: Problem, loitering: set[OperationId]) -> None:
        self.ctx = ctx
        self.pb = pb
        self.loitering = loitering
        self.queue: list[Queued] = []

    def mobility(self, op: Operation) -> float:
        if op.priority >= self.ctx.config.immovable_priority or op.id in self.loitering:
            return 0.0
        return 1.0 / max(op.priority, 1)

    def alone(self, k: int) -> None:
        """Single-mover scenarios of member ``k``: up, down, left, right, then timing."""
        pb = self.pb
        u = len(pb.members)
        op = pb.members[k]
        only = [j == k for j in range(u)]
        for axis, sign in _ALONE:
            signs = [sign if j == k else 0 for j in range(u)]
            self.run([axis] * u, signs, only, f"{op.id} alone")
        rigid = [o for o in pb.members if o.id != op.id]
        self.queue += timing_candidates(self.ctx, op, pb, rigid)

    def cord(
        self, op: Operation, plan: LocalPlan, axis: cd.Axis, sign: int, mobile: bool
    ) -> cd.Cord:
        cfg = self.ctx.config
        lo, hi = self.ctx.alt_limits(op)
        vertical = axis is cd.Axis.VERTICAL
        slope = (
            vertical_slope(op, cfg)
            if vertical
            else cd.lateral_slope(op.cruise_speed_mps, cfg.cord_dt_s, cfg.max_lateral_angle_deg)
        )
        return cd.Cord(
            plan=plan,
            axis=axis if mobile else cd.Axis.NONE,
            sign=sign,
            mobility=self.mobility(op) if mobile else 0.0,
            slope_m_per_step=slope,
            max_offset_m=cfg.max_vertical_offset_m if vertical else cfg.max_lateral_offset_m,
            min_alt_amsl_m=lo,
            max_alt_amsl_m=hi,
        )

    def run(self, axes: list[cd.Axis], signs: list[int], mobile: list[bool], label: str) -> None:
        """One charged-cord scenario; every deformed member's plan is queued."""
        pb, cfg = self.pb, self.ctx.config
        cords = [
            self.cord(op, pb.local[op.id], axes[k], signs[k], mobile[k])
            for k, op in enumerate(pb.members)
        ]
        res = cd.resolve(
            cords,
            pb.grid,
            pb.minima,
            spherical=self.ctx.monitoring.spherical,
            margin_fraction=cfg.separation_margin_fraction,
            max_iterations=cfg.max_iterations,
            problem=pb.prepared,
        )
        if res is None:
            for k, op in enumerate(pb.members):
                if mobile[k] and op.id in pb.involved:
                    self.queue.append(
                        Dropped(
                            operation_id=op.id,
                            maneuver=Maneuver.KEEP_PLAN,
                            reason=f"{label}: no convergence",
                        )
                    )
            return
        for k, op in enumerate(pb.members):
            dk = res.displacement_m[k]
            axis = cords[k].axis
            if axis is cd.Axis.NONE or float(dk.max()) < 0.5:
                continue
            sign = res.signs[k]
            man = _MANEUVER[axis, 1 if sign > 0 else -1]
            self.queue.append(
                self.ctx.candidate(
                    op,
                    man,
                    deform(op, pb.local[op.id], pb.grid, dk, axis, sign, cfg),
                    pb.local[op.id],
                    geofences=pb.geofences,
                    fences=pb.fences,
                    outsiders=pb.outsiders,
                    lowest_priority=pb.lowest,
                    detail=f"{label}: {man.value} up to {float(dk.max()):.0f} m",
                    dest=pb.out[op.id],
                )
            )


def cord_candidates(
    ctx: Context, threat: Threat, snapshot: AirspaceSnapshot
) -> tuple[list[Queued], dict[OperationId, list[Alternative]]]:
    """The candidates of every UAS of the conflict and of the neighbours drawn into it, and
    the lists their alternatives go to once verified. Every UAS gets ``KEEP_PLAN`` so that
    EM's joint selection can leave the higher-priority UAS alone. New plans start at the
    context's start time: where each UAS will be when it gets the plan."""
    t0 = ctx.start_t_s
    cfg = ctx.config
    ctx.air.at(snapshot)
    involved = [
        lt.involved(op, snapshot, ctx.frame, t0 + cfg.horizon_s)
        for op in (snapshot.operations[i] for i in threat.uas_ids if i in snapshot.operations)
    ]
    loitering = {op.id for op in involved if op is not snapshot.operations[op.id]}
    if not involved:
        return [], {}
    pb = _problem(ctx, involved, snapshot)
    # A neighbour whose vehicle is not heard cannot take a plan: rigid, like a loiter (.unheard)
    rigid = loitering | unheard(snapshot, involved, pb.members[len(involved) :])
    sc = _Scenarios(ctx, pb, rigid)
    for op in pb.members:
        # Keeping the plan moves nothing: no priority price (the score's cost is then 0).
        lp = pb.local[op.id]
        sc.queue.append(
            Candidate(
                op=op,
                maneuver=Maneuver.KEEP_PLAN,
                new=lp,
                old=lp,
                geofences=pb.geofences,
                fences=pb.fences,
                outsiders=pb.outsiders,
                lowest_priority=op.priority,
                detail="keep the current plan",
                dest=pb.out[op.id],
                keep=True,
            )
        )
    u = len(pb.members)
    mobile_all = [sc.mobility(op) > 0 for op in pb.members]
    sc.run([cd.Axis.VERTICAL] * u, [0] * u, mobile_all, "joint vertical repulsion")
    sc.run([cd.Axis.LATERAL] * u, [0] * u, mobile_all, "joint lateral repulsion")
    for k, op in enumerate(pb.members):
        if op.id in pb.involved and mobile_all[k]:
            sc.alone(k)
    return sc.queue, pb.out


def _problem(ctx: Context, involved: list[Operation], snapshot: AirspaceSnapshot) -> Problem:
    """The cord problem of ``involved`` and their neighbours from the start time on."""
    t0, cfg = ctx.start_t_s, ctx.config
    local = {op.id: ctx.local_plan(op.plan).after(t0) for op in involved}
    end = min(t0 + cfg.horizon_s, max(float(lp.t[-1]) for lp in local.values()))
    steps = max(2, math.ceil((end - t0) / cfg.cord_dt_s) + 1)
    grid: FloatArray = t0 + np.arange(steps, dtype=np.float64) * cfg.cord_dt_s
    members = list(involved) + _neighbours(ctx, involved, snapshot, grid)
    for op in members:
        local.setdefault(op.id, ctx.local_plan(op.plan).after(t0))
    u = len(members)
    minima = np.zeros((u, u, 2))
    for i, a in enumerate(members):
        for j, b in enumerate(members):
            minima[i, j] = ctx.pair_minima(a, b)
    return Problem(
        members=members,
        involved={op.id for op in involved},
        local=local,
        grid=grid,
        minima=minima,
        outsiders=ctx.others(snapshot, {op.id for op in members}),
        geofences=snapshot.geofences,
        fences=ctx.local_fences(snapshot.geofences),
        lowest=min(op.priority for op in members),
        out={op.id: [] for op in members},
        # Axes, signs and mobility aside, every scenario works on the same cords.
        prepared=cd.prepare(
            [local[op.id] for op in members],
            grid,
            minima,
            spherical=ctx.monitoring.spherical,
            margin_fraction=cfg.separation_margin_fraction,
        ),
    )


def _neighbours(
    ctx: Context, involved: Sequence[Operation], snapshot: AirspaceSnapshot, grid: FloatArray
) -> list[Operation]:
    """Operations whose plans come within 3x the minima of an involved plan inside the
    horizon: the ones a deformation can push into (nearest first, at most
    ``max_neighbours``)."""
    ids = {op.id for op in involved}
    pos = [ctx.local_plan(op.plan).sample(grid) for op in involved]
    found: list[tuple[float, Operation]] = []
    for other in ctx.others(snapshot, ids):
        p, ok = ctx.local_plan(other.plan).sample(grid)
        best = math.inf
        for op, (q, ok2) in zip(involved, pos, strict=True):
            m = ok & ok2
            if not m.any():
                continue
            h, v = ctx.monitoring.effective_minima(
                op.operational_volume_m, other.operational_volume_m
            )
            dh = np.hypot(p[m, 0] - q[m, 0], p[m, 1] - q[m, 1]) / h
            dv = np.abs(p[m, 2] - q[m, 2]) / v
            best = min(best, float(np.maximum(dh, dv).min()))
        if best < 3.0:
            found.append((best, other))
    found.sort(key=lambda x: x[0])
    return [op for _, op in found[: ctx.config.max_neighbours]]


def dedupe(alts: list[Alternative]) -> list[Alternative]:
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
