"""Moving an end point away from traffic (issue 30 class 1: aircraft after their plan).

An airborne UAS stays in the air after its plan has ended, until it lands: a multirotor
hovers at its last waypoint, a fixed wing circles it at its loiter radius
(:func:`gcs_utm.core.tracking.loiter.loiter_radius_m`). As far as the UTM knows that lasts
indefinitely, and two circles flown at different speeds sweep every relative phase: two such
aircraft keep separation for good only when their end points are apart by the pair's
minima plus both loiter radii horizontally, or by the vertical minimum (:func:`ends_clash`,
TD's buffered minima). No deformation of the plans helps (they keep their end points, and TD
does not move a loitering fixed wing), and holding a fixed wing is circling where it is.

When Monitoring predicts a loss between two airborne UAS after both of their plans have ended
(the predicted event is later than both plan ends) and their end points clash, EM moves one
end point (:func:`move_end`): for each UAS of the pair that may move (below the immovable
priority), the nearest new end point, horizontally on 16 bearings or vertically by the
vertical minimum within the altitude band, whose loiter or hover clears the end point of
every other UAS that is traffic (a fixed wing's by the loop it flies entering its circle,
:mod:`.circle_entry`), and whose plan (from where the UAS is now straight to the new end
point, then the loop and one loiter circle for a fixed wing) TD verifies against the traffic
and the geofences. The lowest priority moves (then the shortest move). The plan is proposed like
any other (maneuver ``move_end``) with the reason in the audit; when no end point is found,
EM goes on with its immediate commands.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan, local_to_plan
from gcs_utm.core.emergency.circle_entry import entry_loop, entry_reach_m
from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.core.tracking.loiter import loiter_radius_m
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FlightPlan,
    FloatArray,
    Maneuver,
    Operation,
    OperationId,
    ThreatKind,
)

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction import TacticalDeconfliction

BEARINGS = 16
"""Directions a new end point is searched in."""
STEP_M = 10.0
"""Spacing of the candidate end points along each bearing."""
MAX_MOVE_M = 800.0
"""Farthest a new end point goes from the old one."""
VERTICAL_MARGIN_M = 5.0
"""A vertical move goes this much beyond the vertical minimum from the clashing end."""
MAX_VERIFIED = 12
"""Candidates verified by TD per UAS (nearest first) before giving up on it."""
CIRCLE_STEP_S = 2.0
"""Spacing in time of the loiter circle appended for verification."""


def end_xyz(td: TacticalDeconfliction, op: Operation) -> FloatArray:
    """The last waypoint of ``op``'s plan (local frame)."""
    out: FloatArray = td.local_plan(op.plan).xyz()[-1]
    return out


def ends_clash(  # noqa: PLR0917 - the pair, then their end points
    td: TacticalDeconfliction,
    a: Operation,
    b: Operation,
    end_a: FloatArray,
    end_b: FloatArray,
    reach_a_m: float | None = None,
) -> bool:
    """Whether ``a`` waiting at ``end_a`` (hovering, or circling it) and ``b`` at ``end_b``
    can come inside TD's minima for the pair, whatever the phases of their circles.
    ``reach_a_m``: how far ``a`` goes from ``end_a`` (its loiter radius when not given)."""
    h_m, v_m = td.pair_minima(a, b)
    dh = math.hypot(float(end_a[0] - end_b[0]), float(end_a[1] - end_b[1]))
    reach_a = loiter_radius_m(a) if reach_a_m is None else reach_a_m
    if td.monitoring.spherical:
        dist = math.hypot(dh - reach_a - loiter_radius_m(b), float(end_a[2] - end_b[2]))
        return dist < h_m
    return dh < h_m + reach_a + loiter_radius_m(b) and abs(float(end_a[2] - end_b[2])) < v_m


def _after_plans(snapshot: AirspaceSnapshot, ops: Sequence[Operation], event_t_s: float) -> bool:
    """Both UAS airborne and the loss predicted after both of their plans have ended."""
    return all(o.id in snapshot.airborne and o.plan.end_t_s <= event_t_s for o in ops)


def _candidates(
    td: TacticalDeconfliction, op: Operation, end: FloatArray, rise_m: float
) -> list[tuple[float, FloatArray]]:
    """(size of the move, new end point) nearest first: horizontal on :data:`BEARINGS`
    bearings every :data:`STEP_M`, and up or down by ``rise_m`` within the altitude band."""
    out: list[tuple[float, FloatArray]] = []
    lo, hi = td.alt_limits(op)
    for dz in (rise_m, -rise_m):
        if lo <= end[2] + dz <= hi:
            out.append((abs(dz), end + np.array([0.0, 0.0, dz])))
    bearings = np.arange(BEARINGS) * (2.0 * math.pi / BEARINGS)
    for d in np.arange(STEP_M, MAX_MOVE_M + STEP_M / 2, STEP_M):
        for b in bearings:
            out.append((float(d), end + np.array([d * math.sin(b), d * math.cos(b), 0.0])))
    out.sort(key=lambda x: x[0])
    return out


def _departure(
    op: Operation, snapshot: AirspaceSnapshot, here: FloatArray, vel: FloatArray, t_go: float
) -> tuple[FloatArray, float]:
    """Where a fixed wing circling its old end point (clockwise, at its loiter radius) is at
    ``t_go``, and its heading (rad, east = 0, counter-clockwise): it goes round until the
    new plan reaches it. A UAS that is not circling goes on at its velocity."""
    now = snapshot.t_s
    radius = loiter_radius_m(op)
    speed = math.hypot(float(vel[0]), float(vel[1]))
    heading = math.atan2(float(vel[1]), float(vel[0])) if speed > 1.0 else 0.0
    dt = max(t_go - now, 0.0)
    if radius <= 0.0 or speed <= 1.0 or op.plan.end_t_s > now:
        return here + np.array([vel[0] * dt, vel[1] * dt, 0.0]), heading
    # clockwise: the centre is to the right of the heading
    cx = here[0] + radius * math.sin(heading)
    cy = here[1] - radius * math.cos(heading)
    phi = math.atan2(here[1] - cy, here[0] - cx) - speed * dt / radius
    at = np.array([cx + radius * math.cos(phi), cy + radius * math.sin(phi), here[2]])
    return at, phi - math.pi / 2.0


def _turn_path(
    start: FloatArray, heading: float, target: FloatArray, radius: float, speed: float
) -> tuple[list[FloatArray], list[float]]:
    """The points (and their time offsets) of a fixed wing's turn at ``radius`` from
    ``start``/``heading`` the shorter way towards ``target``, up to the point where it heads
    straight at it (none when it already does, or ``target`` is inside the turn)."""
    bearing = math.atan2(float(target[1] - start[1]), float(target[0] - start[0]))
    turn = (bearing - heading + math.pi) % (2.0 * math.pi) - math.pi
    if abs(turn) < math.radians(5.0) or radius <= 0.0:
        return [], []
    side = 1.0 if turn > 0 else -1.0  # +1: left (counter-clockwise)
    cx = start[0] - side * radius * math.sin(heading)
    cy = start[1] + side * radius * math.cos(heading)
    dx, dy = float(target[0] - cx), float(target[1] - cy)
    dist = math.hypot(dx, dy)
    if dist <= radius:
        return [], []
    phi0 = math.atan2(start[1] - cy, start[0] - cx)
    # tangent point: the radius there is perpendicular to the line to the target
    phi_t = math.atan2(dy, dx) - side * math.acos(radius / dist)
    sweep = (side * (phi_t - phi0)) % (2.0 * math.pi)
    k = max(1, math.ceil(sweep * radius / speed / CIRCLE_STEP_S))
    pts, dts = [], []
    for j in range(1, k + 1):
        a = phi0 + side * sweep * j / k
        pts.append(np.array([cx + radius * math.cos(a), cy + radius * math.sin(a), start[2]]))
        dts.append(sweep * radius / speed * j / k)
    return pts, dts


def _transit(
    em: EmContext, op: Operation, snapshot: AirspaceSnapshot, new_end: FloatArray
) -> tuple[FlightPlan, FlightPlan] | None:
    """(the plan to upload, the plan to verify: the same followed by one loiter circle for a
    fixed wing): from where the UAS is now to ``new_end`` at its cruise speed (its climb or
    descent rate when slower) from when it can have the plan; a fixed wing goes round its
    circle until then and turns towards the new end point (:func:`_turn_path`). None without
    a fresh track."""
    td = em.td
    now = snapshot.t_s
    track = next(
        (t for t in snapshot.tracks.values() if t.operation_id == op.id and not t.stale), None
    )
    if track is None:
        return None
    here = td.current_xyz(op, snapshot)
    vel = np.asarray(track.vel_enu_mps, dtype=np.float64)
    env = op.performance()
    speed = max(op.cruise_speed_mps, 1e-3)
    t_go = max(em.earliest_receipt(now, (op.id,)), now)
    radius = loiter_radius_m(op)
    go, heading = _departure(op, snapshot, here, vel, t_go)
    pts, dts = [here], [now]
    if radius > 0.0 and t_go > now:
        pts.append(go)
        dts.append(t_go)
    turn, turn_dt = _turn_path(pts[-1], heading, new_end, radius, speed)
    pts += turn
    dts += [dts[-1] + x for x in turn_dt]
    dh = math.hypot(float(new_end[0] - pts[-1][0]), float(new_end[1] - pts[-1][1]))
    dz = float(new_end[2] - here[2])
    rate = env.climb_rate_mps if dz > 0 else env.descent_rate_mps
    fly_s = max(dh / speed, abs(dz) / max(rate, 1e-3) - (dts[-1] - t_go), 1.0)
    pts.append(new_end)
    dts.append(max(dts[-1], t_go) + fly_s)
    xyz = np.array(pts)
    # the altitude changes linearly from now to the new end point
    t_arr = np.array(dts)
    xyz[:, 2] = np.interp(t_arr, [now, t_arr[-1]], [here[2], new_end[2]])
    lp = LocalPlan(xyz[:, 0].copy(), xyz[:, 1].copy(), xyz[:, 2].copy(), t_arr)
    plan = local_to_plan(lp, op.plan, td.frame, created_t_s=now, reason="move_end")
    if radius <= 0.0:
        return plan, plan
    # for verification: the loop onto the circle (.circle_entry), then one clockwise circle
    # round the new end point at cruise speed
    t_end = float(t_arr[-1])
    arrive = math.atan2(float(new_end[1] - xyz[-2, 1]), float(new_end[0] - xyz[-2, 0]))
    le, ln, lt = entry_loop(new_end, arrive, radius, speed, CIRCLE_STEP_S)
    t_in = t_end + float(lt[-1])
    lap_s = 2.0 * math.pi * radius / speed
    times = t_in + np.arange(1, math.ceil(lap_s / CIRCLE_STEP_S) + 1) * CIRCLE_STEP_S
    on = math.atan2(float(ln[-1] - new_end[1]), float(le[-1] - new_end[0]))
    ang = on - (times - t_in) * speed / radius
    circle = LocalPlan(
        np.concatenate([lp.e, le, new_end[0] + radius * np.cos(ang)]),
        np.concatenate([lp.n, ln, new_end[1] + radius * np.sin(ang)]),
        np.concatenate([lp.z, np.full(len(lt) + len(times), new_end[2])]),
        np.concatenate([lp.t, t_end + lt, times]),
    )
    return plan, local_to_plan(circle, op.plan, td.frame, created_t_s=now, reason="move_end")


def _best_end(
    em: EmContext, op: Operation, snapshot: AirspaceSnapshot
) -> tuple[float, Alternative] | None:
    """The nearest verified end point for ``op`` (see the module docstring)."""
    td = em.td
    others = td.others(snapshot, {op.id})
    # (their filed or current plans' end points: td.others extends them past their end)
    ends = [(o, end_xyz(td, snapshot.operations.get(o.id, o))) for o in others]
    end = end_xyz(td, op)
    rise = max((td.pair_minima(op, o)[1] for o, _ in ends), default=0.0)
    reach = entry_reach_m(loiter_radius_m(op), op.cruise_speed_mps)  # it loops out entering
    verified = 0
    for size, cand in _candidates(td, op, end, rise + VERTICAL_MARGIN_M):
        if any(ends_clash(td, op, o, cand, e, reach) for o, e in ends):
            continue
        plans = _transit(em, op, snapshot, cand)
        if plans is None or verified >= MAX_VERIFIED:
            return None
        verified += 1
        if td.verify(plans[1], op, others, snapshot.geofences):
            continue
        how = "up" if cand[2] > end[2] + 1e-6 else "down" if cand[2] < end[2] - 1e-6 else ""
        detail = f"end point moved {size:.0f} m {how or 'across'} away from traffic"
        alt = Alternative(
            operation_id=op.id,
            maneuver=Maneuver.MOVE_END,
            plan=plans[0],
            cost=size / MAX_MOVE_M,
            risk=0.0,
            detail=detail,
            offset_m=size,
        )
        return size, alt
    return None


def move_end(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision | None:
    """The recommendation moving one end point of a loss predicted between two UAS after
    their plans (see the module docstring), or None when that is not the case or no end point
    is found."""
    t = case.threat
    ops = [snapshot.operations.get(u) for u in t.uas_ids]
    pair = [o for o in ops if o is not None]
    event = t.predicted_event_at_s
    td = em.td
    if (
        t.kind is not ThreatKind.LOSS_OF_SEPARATION
        or event is None
        or len(pair) != 2
        or not _after_plans(snapshot, pair, event)
        or not ends_clash(td, pair[0], pair[1], end_xyz(td, pair[0]), end_xyz(td, pair[1]))
    ):
        return None
    found: list[tuple[int, float, str, Alternative]] = []
    for op in pair:
        if op.priority >= td.config.immovable_priority:
            continue
        best = _best_end(em, op, snapshot)
        if best is not None:
            found.append((op.priority, best[0], str(op.id), best[1]))
    now = snapshot.t_s
    names = ", ".join(t.uas_ids)
    if not found:
        return None
    found.sort(key=lambda x: x[:3])
    _, _, who, alt = found[0]
    mover = OperationId(who)
    reason = (
        f"{t.kind.value}: {names} wait after their plans with end points that clash "
        f"(loss predicted at +{event - now:.0f} s): {mover}'s {alt.detail}"
    )
    detail: dict[str, object] = {"reason": reason, "selected": {who: alt.maneuver.value}}
    detail["moves"] = [{"operation_id": f[2], "move_m": round(f[1], 1)} for f in found]
    case.operations = dict(snapshot.operations)
    d = Decision(audit=(em.audit(now, "decision", t.id, detail),))
    return d.merge(em.issue(case, mover, now, selected=alt, reason=reason))
