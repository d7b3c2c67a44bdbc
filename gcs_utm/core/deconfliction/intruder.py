"""Avoidance of a non-cooperative intruder (paper §4.5): the UAS's cord alone climbs,
descends or moves left or right (the intruder is a rigid cord on its predicted path) until the
intruder minima hold, within the vehicle's envelope (climb share, lateral angle, altitude band
and safety floor). Every candidate is then checked against the intruder's predicted path at
1 s steps: a re-timed plan that no longer keeps the minima is dropped. Pure."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction.context import Context, Dropped, Queued, deform
from gcs_utm.core.deconfliction.geometry import LocalPlan, plan_to_local
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FloatArray,
    Maneuver,
    Operation,
    OperationId,
    Threat,
)

_CANDIDATES = (
    (cd.Axis.VERTICAL, 1, Maneuver.GO_UP),
    (cd.Axis.VERTICAL, -1, Maneuver.GO_DOWN),
    (cd.Axis.LATERAL, 1, Maneuver.GO_LEFT),
    (cd.Axis.LATERAL, -1, Maneuver.GO_RIGHT),
)


def intruder_plan(threat: Threat, snapshot: AirspaceSnapshot, horizon_s: float) -> LocalPlan | None:
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
    ve, vn, vu = tr.vel_enu_mps
    return LocalPlan(
        np.array([tr.east_m, tr.east_m + ve * horizon_s]),
        np.array([tr.north_m, tr.north_m + vn * horizon_s]),
        np.array([tr.alt_amsl_m, tr.alt_amsl_m + vu * horizon_s]),
        np.array([tr.t_s, tr.t_s + horizon_s]),
    )


@dataclass(slots=True)
class Avoidance:
    """The candidates of one intruder avoidance (``queue``), the list their alternatives go
    to once verified (``out``), and what :meth:`kept` checks those against."""

    queue: list[Queued] = field(default_factory=list)
    out: list[Alternative] = field(default_factory=list)
    intruder: LocalPlan | None = None
    minima_m: tuple[float, float] = (0.0, 0.0)

    def kept(
        self, frame: LocalFrame, from_t_s: float, now_t_s: float
    ) -> tuple[list[Alternative], list[Dropped]]:
        """The verified alternatives that hold the intruder minima against its predicted
        path from ``from_t_s`` (:func:`loses_minima`), and the others, dropped."""
        kept: list[Alternative] = []
        dropped: list[Dropped] = []
        if self.intruder is None:
            return kept, dropped
        for alt in self.out:
            lost = loses_minima(alt, self.intruder, frame, from_t_s, self.minima_m)
            if lost is None:
                kept.append(alt)
            else:
                dropped.append(
                    Dropped(
                        operation_id=alt.operation_id,
                        maneuver=alt.maneuver,
                        reason=f"intruder minima lost at t={lost - now_t_s:+.1f} s",
                    )
                )
        return kept, dropped


def intruder_candidates(
    ctx: Context, threat: Threat, operation_id: OperationId, snapshot: AirspaceSnapshot
) -> Avoidance:
    """Go up, go down, go left and go right candidates for ``operation_id``; once TD has
    verified and scored them, :meth:`Avoidance.kept` keeps those that hold the intruder
    minima. New plans start at the context's start time."""
    op = snapshot.operations.get(operation_id)
    intruder = intruder_plan(threat, snapshot, ctx.config.horizon_s)
    if op is None or intruder is None:
        return Avoidance()
    t0 = ctx.start_t_s
    cfg = ctx.config
    lp = ctx.local_plan(op.plan).after(t0)
    end = min(t0 + cfg.horizon_s, float(lp.t[-1]))
    steps = max(2, math.ceil((end - t0) / cfg.cord_dt_s) + 1)
    grid: FloatArray = t0 + np.arange(steps, dtype=np.float64) * cfg.cord_dt_s
    mon = ctx.monitoring
    h_min = max(mon.intruder_horizontal_m, op.operational_volume_m)
    v_min = max(mon.intruder_vertical_m, op.operational_volume_m)
    minima = np.array([[[h_min, v_min]] * 2] * 2)
    lo, hi = ctx.alt_limits(op)
    outsiders = ctx.others(snapshot, {op.id})
    fences = ctx.local_fences(snapshot.geofences)
    got = Avoidance(intruder=intruder, minima_m=(h_min, v_min))
    rigid = cd.Cord(
        plan=intruder,
        axis=cd.Axis.NONE,
        sign=0,
        mobility=0.0,
        slope_m_per_step=0.0,
        max_offset_m=0.0,
        min_alt_amsl_m=lo,
        max_alt_amsl_m=hi,
    )
    for axis, sign, man in _CANDIDATES:
        vertical = axis is cd.Axis.VERTICAL
        mine = cd.Cord(
            plan=lp,
            axis=axis,
            sign=sign,
            mobility=1.0,
            slope_m_per_step=_vertical_slope(op, sign, cfg.cord_dt_s)
            if vertical
            else cd.lateral_slope(op.cruise_speed_mps, cfg.cord_dt_s, cfg.max_lateral_angle_deg),
            max_offset_m=cfg.max_vertical_offset_m if vertical else cfg.max_lateral_offset_m,
            min_alt_amsl_m=lo,
            max_alt_amsl_m=hi,
        )
        res = cd.resolve(
            [mine, rigid],
            grid,
            minima,
            spherical=False,
            margin_fraction=cfg.separation_margin_fraction,
            max_iterations=cfg.max_iterations,
        )
        if res is None:
            reason = "no convergence within the envelope"
            got.queue.append(Dropped(operation_id=op.id, maneuver=man, reason=reason))
            continue
        dk = res.displacement_m[0]
        got.queue.append(
            ctx.candidate(
                op,
                man,
                deform(op, lp, grid, dk, axis, sign, cfg),
                lp,
                geofences=snapshot.geofences,
                fences=fences,
                outsiders=outsiders,
                lowest_priority=op.priority,
                detail=f"avoidance of intruder {threat.intruder_id}: "
                f"{man.value} {float(dk.max()):.0f} m",
                dest=got.out,
            )
        )
    return got


def _vertical_slope(op: Operation, sign: int, dt_s: float) -> float:
    """Metres per cord step of an intruder avoidance: the vehicle's full climb (or descent)
    rate, not the share left by other deformations (an intruder leaves no time to spare; the
    re-timed plan stays inside the envelope and :func:`loses_minima` checks its timing)."""
    env = op.performance()
    return (env.climb_rate_mps if sign > 0 else env.descent_rate_mps) * dt_s


def loses_minima(
    alt: Alternative,
    intruder: LocalPlan,
    frame: LocalFrame,
    from_t_s: float,
    minima_m: tuple[float, float],
) -> float | None:
    """The first time (1 s steps from ``from_t_s``) ``alt``'s plan is inside the intruder
    minima (horizontal and vertical at once) of the intruder's predicted path; None when it
    never is."""
    if alt.plan is None:
        return None
    mine = plan_to_local(alt.plan, frame)
    end = min(float(mine.t[-1]), float(intruder.t[-1]))
    if end <= from_t_s:
        return None
    times: FloatArray = np.arange(from_t_s, end + 1e-9, 1.0)
    a, ok_a = mine.sample(times)
    b, ok_b = intruder.sample(times)
    dh = np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1])
    dv = np.abs(a[:, 2] - b[:, 2])
    inside = ok_a & ok_b & (dh < minima_m[0]) & (dv < minima_m[1])
    hit = np.flatnonzero(inside)
    return float(times[hit[0]]) if hit.size else None
