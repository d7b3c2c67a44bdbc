"""Vertical avoidance of a non-cooperative intruder (paper §4.5): the UAS's cord alone climbs
or descends (the intruder is a rigid cord) until the intruder minima hold. Pure."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FloatArray,
    Maneuver,
    OperationId,
    Threat,
)

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction.td import TacticalDeconfliction


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


def resolve_intruder(
    td: TacticalDeconfliction,
    threat: Threat,
    operation_id: OperationId,
    snapshot: AirspaceSnapshot,
    start_t_s: float | None = None,
) -> list[Alternative]:
    """Go up and go down candidates for ``operation_id``, verified and scored by ``td``; the
    new plan starts at ``start_t_s`` (see :meth:`TacticalDeconfliction.start_time`)."""
    td.dropped = []
    td.reset_queue()
    op = snapshot.operations.get(operation_id)
    intruder = intruder_plan(threat, snapshot, td.config.horizon_s)
    if op is None or intruder is None:
        return []
    t0 = td.start_time(snapshot, start_t_s)
    cfg = td.config
    lp = td.local_plan(op.plan).after(t0)
    end = min(t0 + cfg.horizon_s, float(lp.t[-1]))
    steps = max(2, math.ceil((end - t0) / cfg.cord_dt_s) + 1)
    grid: FloatArray = t0 + np.arange(steps, dtype=np.float64) * cfg.cord_dt_s
    mon = td.monitoring
    h_min = max(mon.intruder_horizontal_m, op.operational_volume_m)
    v_min = max(mon.intruder_vertical_m, op.operational_volume_m)
    minima = np.array([[[h_min, v_min]] * 2] * 2)
    lo, hi = td.alt_limits(op)
    outsiders = td.others(snapshot, {op.id})
    fences = td.local_fences(snapshot.geofences)
    out: list[Alternative] = []
    for sign in (1, -1):
        mine = cd.Cord(
            plan=lp,
            axis=cd.AXIS_VERTICAL,
            sign=sign,
            mobility=1.0,
            slope_m_per_step=td.vertical_slope(op),
            max_offset_m=cfg.max_vertical_offset_m,
            min_alt_amsl_m=lo,
            max_alt_amsl_m=hi,
        )
        rigid = cd.Cord(
            plan=intruder,
            axis=cd.AXIS_NONE,
            sign=0,
            mobility=0.0,
            slope_m_per_step=0.0,
            max_offset_m=0.0,
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
        man = Maneuver.GO_UP if sign > 0 else Maneuver.GO_DOWN
        if res is None:
            td.drop(op.id, man, "no convergence")
            continue
        dk = res.displacement_m[0]
        td.finish(
            op,
            man,
            td.deform(op, lp, grid, dk, cd.AXIS_VERTICAL, sign),
            lp,
            geofences=snapshot.geofences,
            fences=fences,
            outsiders=outsiders,
            lowest_priority=op.priority,
            detail=f"vertical avoidance of intruder {threat.intruder_id}: "
            f"{man.value} {float(dk.max()):.0f} m",
            dest=out,
        )
    td.flush(snapshot.t_s)
    return out
