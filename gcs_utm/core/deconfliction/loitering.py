"""An airborne UAS whose plan has ended, as traffic: its loiter circle or its hover, not its
plan's end.

A UAS in the air is traffic from take-off to landing whatever its plan says
(``AirspaceSnapshot.airborne``, from its own messages): after its plan ends a multirotor
hovers at the last waypoint (:func:`hover_plan`) and a fixed wing circles it (below). Until
its circle is seen on its track a fixed wing is taken at the last waypoint, its circle's
centre. An operation ends when its vehicle lands or disarms, not when its last waypoint time
passes.

A fixed wing cannot stop: when its mission ends the autopilot circles the last waypoint at the
loiter radius (:mod:`gcs_utm.core.tracking.loiter`), and Tracking predicts it there. Its filed
plan, sampled past its end, is one point (or nothing): candidates and keep-plan judged
against that plan see no conflict with an aircraft that is in fact flying round a circle of
up to a turn radius around that point, and an involved UAS that passes through the circle is
left on its plan.

:func:`loiter_plan` gives each such operation a plan that goes on round the circle up to a
time (the decision's horizon): its filed waypoints, then timed points on the circle the
tracker predicts (the same geometry, :func:`.loiter.loiter_rows` and
:func:`.loiter.loiter_points`: centre the last waypoint, phase and turn from the track,
angular speed from its ground speed, offsets converging with the plan-following time
constant). TD takes the other UAS of a decision with these plans (:func:`traffic`), and an
involved loitering aircraft too (:func:`as_traffic`), which it does not move (its new plan
would be a deformed circle): the others are kept clear of it.

Units: local frame metres (east, north, alt AMSL), seconds.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import replace

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan, local_to_plan, plan_to_local
from gcs_utm.core.tracking import loiter
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Operation,
    OperationId,
    OperationState,
    Track,
    Waypoint4D,
)

CIRCLE_STEP_S = 2.0
"""Spacing of the circle's points in time: at a fixed wing's speed on its turn radius a chord
of this length lies within two metres of the arc."""

CONVERGE_S = 10.0
"""Time constant with which the track's offset from the circle shrinks (the tracker's
``plan_offset_decay_s`` default): only the first seconds of the circle depend on it."""


def _track_of(op: Operation, snapshot: AirspaceSnapshot) -> Track | None:
    for tr in snapshot.tracks.values():
        if tr.operation_id == op.id and not tr.stale:
            return tr
    return None


def loiter_plan(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, until_t_s: float
) -> FlightPlan | None:
    """``op``'s plan followed by its loiter circle up to ``until_t_s``, or None when it is not
    loitering at the snapshot (not a fixed wing, plan not ended, no fresh track, track away
    from the last waypoint or too slow to tell its turn: :func:`.loiter.loiter_rows`)."""
    radius = loiter.loiter_radius_m(op)
    if radius <= 0.0 or op.plan.end_t_s > snapshot.t_s:
        return None
    tr = _track_of(op, snapshot)
    if tr is None:
        return None
    e, n = frame.point_to_local(tr.lat_deg, tr.lon_deg)
    pos = np.array([[e, n, tr.alt_amsl_m]])
    vel = np.array([tr.vel_enu_mps], dtype=np.float64)
    lp = plan_to_local(op.plan, frame)
    center = lp.xyz()[-1:]
    radius_m = np.array([radius])
    rows = loiter.loiter_rows(
        radius_m=radius_m,
        t_state_s=np.array([snapshot.t_s]),
        end_t_s=np.array([op.plan.end_t_s]),
        pos=pos,
        vel=vel,
        center=center,
    )
    t_from = max(tr.t_s, op.plan.end_t_s + 1e-3)
    if not len(rows) or until_t_s <= t_from:
        return None
    k = max(2, math.ceil((until_t_s - t_from) / CIRCLE_STEP_S) + 1)
    times = np.linspace(t_from, until_t_s, k)
    east, north, alt = loiter.loiter_points(
        radius_m=radius_m,
        pos=pos,
        vel=vel,
        center=center,
        tau_s=(times - tr.t_s)[None, :],
        decay_s=CONVERGE_S,
    )
    circle = local_to_plan(
        LocalPlan(east[0], north[0], alt[0], times),
        op.plan,
        frame,
        created_t_s=snapshot.t_s,
        reason="loiter",
    )
    return replace(op.plan, waypoints=op.plan.waypoints + circle.waypoints)


def as_traffic(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, until_t_s: float
) -> Operation | None:
    """``op`` with its plan extended by its loiter circle (:func:`loiter_plan`), or None when
    it is not loitering."""
    plan = loiter_plan(op, snapshot, frame, until_t_s)
    return None if plan is None else replace(op, plan=plan)


def hover_plan(plan: FlightPlan, until_t_s: float) -> FlightPlan:
    """``plan`` followed by a hover at its last waypoint up to ``until_t_s`` (``plan`` itself
    when it lasts that long)."""
    last = plan.waypoints[-1]
    if last.t_s >= until_t_s:
        return plan
    return replace(plan, waypoints=(*plan.waypoints, replace(last, t_s=until_t_s)))


def after_plan(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, until_t_s: float
) -> FlightPlan:
    """Where an airborne UAS will be up to ``until_t_s``: where its track is now when its plan
    has not started yet (it waits in the air), its plan, then its loiter circle (a fixed wing
    seen on it) or a hover at its last waypoint. The plan itself for a UAS not in the air
    (``snapshot.airborne``)."""
    if op.id not in snapshot.airborne:
        return op.plan
    circle = loiter_plan(op, snapshot, frame, until_t_s)
    plan = circle if circle is not None else hover_plan(op.plan, until_t_s)
    tr = _track_of(op, snapshot)
    if tr is not None and plan.start_t_s > max(tr.t_s, snapshot.t_s):
        # waiting in the air for its plan: where it is until it must leave, at its cruise
        # speed, to reach its first waypoint on time
        first = plan.waypoints[0]
        e0, n0 = frame.point_to_local(tr.lat_deg, tr.lon_deg)
        e1, n1 = frame.point_to_local(first.lat_deg, first.lon_deg)
        dist_m = math.hypot(e1 - e0, n1 - n0, first.alt_amsl_m - tr.alt_amsl_m)
        leave_t_s = max(snapshot.t_s, plan.start_t_s - dist_m / op.cruise_speed_mps)
        here = Waypoint4D(
            lat_deg=tr.lat_deg, lon_deg=tr.lon_deg, alt_amsl_m=tr.alt_amsl_m, t_s=snapshot.t_s
        )
        plan = replace(plan, waypoints=(here, replace(here, t_s=leave_t_s), *plan.waypoints))
    return plan


def extended(
    op: Operation, plan: FlightPlan, snapshot: AirspaceSnapshot, until_t_s: float
) -> FlightPlan:
    """``plan`` (an alternative of ``op``) with the hover after its end up to ``until_t_s``
    when ``op`` is airborne: what the UAS does when it gets there."""
    return hover_plan(plan, until_t_s) if op.id in snapshot.airborne else plan


def involved(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, until_t_s: float
) -> Operation:
    """An involved UAS as TD takes it: with its loiter circle (:func:`as_traffic`), or, airborne
    with its plan ended, hovering at the end point (TD moves neither); else ``op``."""
    circling = as_traffic(op, snapshot, frame, until_t_s)
    if circling is not None:
        return circling
    if op.id in snapshot.airborne and op.plan.end_t_s <= snapshot.t_s:
        return replace(op, plan=hover_plan(op.plan, until_t_s))
    return op


def traffic(
    snapshot: AirspaceSnapshot,
    exclude: Collection[OperationId],
    frame: LocalFrame,
    until_t_s: float,
    inactive: Collection[OperationState],
) -> list[Operation]:
    """The operations other than ``exclude`` that are traffic at the snapshot: airborne ones
    (whatever their plan and state: :func:`after_plan` up to ``until_t_s``), loitering fixed
    wings with their circle, and active ones whose plan has not ended; never one on the
    ground (``snapshot.grounded``)."""
    out = []
    for op in snapshot.operations.values():
        if op.id in exclude or op.id in snapshot.grounded:
            continue  # (a vehicle on the ground is not traffic, whatever its plan says)
        if op.id in snapshot.airborne:
            plan = after_plan(op, snapshot, frame, until_t_s)
            out.append(op if plan is op.plan else replace(op, plan=plan))
            continue
        circling = as_traffic(op, snapshot, frame, until_t_s)
        if circling is not None:
            out.append(circling)
        elif op.state not in inactive and op.plan.end_t_s >= snapshot.t_s:
            out.append(op)
    return out


class Airborne:
    """Which UAS of the snapshot being decided are airborne, and their plans extended past
    their end with a hover (:func:`extended`) up to the decision's horizon, kept so that one
    plan is extended (and converted) once per decision."""

    def __init__(self, horizon_s: float) -> None:
        self.horizon_s = horizon_s
        self._snapshot: AirspaceSnapshot | None = None
        self._plans: dict[int, tuple[FlightPlan, FlightPlan]] = {}

    def until(self, snapshot: AirspaceSnapshot) -> float:
        """The end of the decision's horizon on ``snapshot``, now the one being decided (TD
        takes the traffic first in every decision: single UAS and intruders too)."""
        self.at(snapshot)
        return snapshot.t_s + self.horizon_s

    def at(self, snapshot: AirspaceSnapshot) -> None:
        """The snapshot being decided (also for :meth:`extend` calls without one)."""
        if snapshot is not self._snapshot:
            self._snapshot = snapshot
            self._plans.clear()

    def extend(
        self, op: Operation, plan: FlightPlan, snapshot: AirspaceSnapshot | None = None
    ) -> FlightPlan:
        """``plan`` of ``op``, with the hover after it when ``op`` is airborne."""
        if snapshot is not None:
            self.at(snapshot)
        snap = self._snapshot
        if snap is None or op.id not in snap.airborne:
            return plan
        hit = self._plans.get(id(plan))
        if hit is None or hit[0] is not plan:
            hit = (plan, extended(op, plan, snap, snap.t_s + self.horizon_s))
            self._plans[id(plan)] = hit
        return hit[1]
