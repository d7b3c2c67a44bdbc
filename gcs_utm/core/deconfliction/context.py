"""What Tactical Deconfliction's strategies are given and what they return.

The strategies (:mod:`.multi` charged cords, :mod:`.timing`, :mod:`.single`,
:mod:`.intruder`) each receive one call's :class:`Context` (the local frame, the
configurations, whether the vehicles' tracking tolerances are kept free, the start time and
lead-in of new plans, the shared plan cache and airborne traffic) and return
:class:`Candidate` s and :class:`Dropped` s in the order they made them. They import this
module, never :mod:`.td`: :class:`~.td.TacticalDeconfliction` builds the context, calls the
strategies and has what they return verified and scored (:mod:`.verify`).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, field

import numpy as np

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction import loitering as lt
from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.deform import deformed
from gcs_utm.core.deconfliction.geometry import (
    LocalFence,
    LocalPlan,
    fence_to_local,
)
from gcs_utm.core.deconfliction.lead_times import lead_times, needs_lead_in
from gcs_utm.core.deconfliction.plan_cache import PlanCache
from gcs_utm.core.deconfliction.tolerance import pair_buffers
from gcs_utm.core.monitoring.config import MonitoringConfig
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
)

INACTIVE = (OperationState.LANDED, OperationState.ENDED)
LEAD_IN_STEP_S = 5.0
"""Spacing of a new plan's lead-in points: the untimed first leg a vehicle flies after it
gets the plan is at most this long."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Dropped:
    """A candidate that was generated but not offered, and why."""

    operation_id: OperationId
    maneuver: Maneuver
    reason: str


@dataclass(slots=True, kw_only=True, eq=False)
class Candidate:
    """A new plan waiting for Monitoring's verification and for its score
    (:meth:`.verify.Verifier.flush`); ``keep`` marks the filed plan itself (no conversion,
    verified against every geofence, cost 0). The alternative, if any, is appended to
    ``dest``."""

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
    lead: LocalPlan | None = None
    """Timed points of the plan as flown before ``new`` starts (see :meth:`Context.lead_in`):
    part of the plan the vehicle gets, not of what is scored or envelope-checked."""

    def full(self) -> LocalPlan:
        if self.lead is None or len(self.lead) == 0:
            return self.new
        b = self.new
        a = self.lead
        keep = a.t < b.t[0] - 1e-6  # a plan already over starts before the start time
        if not keep.all():
            a = LocalPlan(a.e[keep], a.n[keep], a.z[keep], a.t[keep])
        return LocalPlan(
            np.concatenate([a.e, b.e]),
            np.concatenate([a.n, b.n]),
            np.concatenate([a.z, b.z]),
            np.concatenate([a.t, b.t]),
        )


Queued = Candidate | Dropped
"""What a strategy returns, in the order it made them."""


@dataclass(slots=True, kw_only=True, eq=False)
class Problem:
    """One charged-cord problem (:mod:`.multi`, :mod:`.timing`): the members (involved UAS
    and the neighbours drawn in), their plans from the start time on, the common grid and
    minima, what lies outside the problem, and the alternatives collected per member."""

    members: list[Operation]
    involved: set[OperationId]
    local: dict[OperationId, LocalPlan]
    grid: FloatArray
    minima: FloatArray
    outsiders: list[Operation]
    geofences: Sequence[Geofence]
    fences: list[LocalFence]
    lowest: int
    out: dict[OperationId, list[Alternative]]
    prepared: cd.Problem


@dataclass(slots=True)
class LeadIn:
    """The window new plans get timed lead-in points for: from ``from_t_s`` (the earliest
    the vehicle can have the plan) to ``start_t_s``, and how far each UAS is off its plan
    now (:meth:`Context.start_xyz`)."""

    from_t_s: float
    start_t_s: float
    offsets: dict[OperationId, FloatArray] = field(default_factory=dict)


def start_time(snapshot: AirspaceSnapshot, start_t_s: float | None) -> float:
    """When a new plan starts: ``start_t_s`` (the decision time plus the expected answer,
    upload and margin, from EM), never before the snapshot."""
    return snapshot.t_s if start_t_s is None else max(snapshot.t_s, start_t_s)


def lead_in_window(from_t_s: float | None, start_t_s: float) -> LeadIn | None:
    """The lead-in of new plans starting at ``start_t_s`` that the vehicle can have from
    ``from_t_s`` on; None when they need none (see :mod:`.lead_times`)."""
    if from_t_s is None or not needs_lead_in(from_t_s, start_t_s):
        return None
    return LeadIn(from_t_s, start_t_s)


def floor_amsl(op: Operation, frame: LocalFrame, config: DeconflictionConfig) -> float:
    """The safety floor: home altitude (else the airspace's ground elevation) plus the
    configured minimum height above home."""
    home = op.home.alt_amsl_m if op.home is not None else frame.ground_elevation_amsl_m
    return home + config.min_height_above_home_m


def alt_limits(
    op: Operation, frame: LocalFrame, config: DeconflictionConfig
) -> tuple[float, float]:
    """Altitude band a deformation stays in: the operation's band (else the airspace's),
    never below the safety floor."""
    lo = op.min_alt_amsl_m if op.min_alt_amsl_m is not None else config.min_alt_amsl_m
    hi = op.max_alt_amsl_m if op.max_alt_amsl_m is not None else config.max_alt_amsl_m
    return max(lo, floor_amsl(op, frame, config)), hi


def pair_minima(
    monitoring: MonitoringConfig, a: Operation, b: Operation, *, buffered: bool
) -> tuple[float, float]:
    """(horizontal, vertical) minima TD keeps between the plans of ``a`` and ``b``: the
    pair's effective minima (one definition of loss, :mod:`..monitoring.loss`), plus, when
    ``buffered``, the two vehicles' tracking tolerances, horizontal and vertical (sphere
    mode: horizontal on the 3D distance). A plan is flown with a lag at its corners and an
    altitude error; a candidate keeping only the bare minima is flown into a loss by a few
    metres. EM searches without them when no combination keeps them."""
    h, v = monitoring.effective_minima(a.operational_volume_m, b.operational_volume_m)
    if not buffered:
        return h, v
    return pair_buffers(a.performance(), b.performance(), h, v, monitoring.spherical)


def current_xyz(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, plans: PlanCache
) -> FloatArray:
    """Where the UAS is now: its track if tracked, else its plan at the snapshot time."""
    for tr in snapshot.tracks.values():
        if tr.operation_id == op.id and not tr.stale:
            e, n = frame.point_to_local(tr.lat_deg, tr.lon_deg)
            return np.array([e, n, tr.alt_amsl_m])
    return plans.local(op.plan).position_at(snapshot.t_s)


def vertical_slope(op: Operation, config: DeconflictionConfig) -> float:
    """Metres per cord step of a vertical deformation: a share of the climb rate. The cord
    only shapes the deformation; the new plan's timing keeps it inside the envelope
    (:func:`.deform.deformed` re-times climbs and descents at their own rates) and that
    re-timed plan is what Monitoring verifies."""
    rate = op.performance().climb_rate_mps
    return rate * config.climb_fraction * config.cord_dt_s


def deform(  # noqa: PLR0917 - positional like the cord's description
    op: Operation,
    lp: LocalPlan,
    grid: FloatArray,
    d: FloatArray,
    axis: cd.Axis,
    sign: int,
    config: DeconflictionConfig,
) -> LocalPlan:
    """The plan through a displaced cord, re-timed inside the vehicle's envelope."""
    return deformed(
        lp,
        grid,
        d,
        axis,
        sign,
        cruise_speed_mps=op.cruise_speed_mps,
        envelope=op.performance(),
        max_speed_factor=config.max_speed_factor,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class Context:
    """One TD call as the strategies see it. ``start_t_s`` is when new plans start (see
    :func:`start_time`); ``buffered`` keeps the tracking tolerances in the pair minima
    (:func:`pair_minima`); ``plans`` and ``air`` are TD's, shared between calls."""

    frame: LocalFrame
    config: DeconflictionConfig
    monitoring: MonitoringConfig
    plans: PlanCache
    air: lt.Airborne
    start_t_s: float
    buffered: bool = True
    lead: LeadIn | None = None

    def local_plan(self, plan: FlightPlan) -> LocalPlan:
        return self.plans.local(plan)

    def local_fences(self, geofences: Sequence[Geofence]) -> list[LocalFence]:
        return [fence_to_local(g, self.frame) for g in geofences]

    def others(
        self, snapshot: AirspaceSnapshot, exclude: Collection[OperationId]
    ) -> list[Operation]:
        """The traffic other than ``exclude``, airborne UAS after their plan (loitering.py)."""
        return lt.traffic(snapshot, exclude, self.frame, self.air.until(snapshot), INACTIVE)

    def alt_limits(self, op: Operation) -> tuple[float, float]:
        return alt_limits(op, self.frame, self.config)

    def pair_minima(self, a: Operation, b: Operation) -> tuple[float, float]:
        return pair_minima(self.monitoring, a, b, buffered=self.buffered)

    def start_xyz(self, op: Operation, snapshot: AirspaceSnapshot) -> FloatArray:
        """Where the UAS will be at the start time: on its plan (as flown) then, offset by
        how far it is off the plan now. For a fixed wing that is ahead along its path, never
        a point it has passed by the time it gets the new plan."""
        t0 = self.start_t_s
        lp = self.local_plan(op.plan)
        ahead = lp.position_at(t0)
        here = current_xyz(op, snapshot, self.frame, self.plans)
        if t0 <= snapshot.t_s:
            return here
        off = here - lp.position_at(snapshot.t_s)
        if self.lead is not None:
            self.lead.offsets[op.id] = off
        return np.asarray(ahead + off, dtype=np.float64)

    def lead_in(self, op: Operation) -> LocalPlan | None:
        """Points of the UAS's plan as flown every LEAD_IN_STEP_S before the start time,
        back to the earliest time the vehicle can have the plan. Missions carry no time: the
        vehicle flies to the first waypoint still ahead when it gets the plan, untimed.
        Without these points that is the start point, up to the whole answer window away
        (a pilot may answer at once): the vehicle arrives early, holds and manoeuvres early.
        With them the untimed leg is at most one step and every later leg keeps its time."""
        if self.lead is None:
            return None
        times: FloatArray = lead_times(self.lead.from_t_s, self.lead.start_t_s, LEAD_IN_STEP_S)
        e, n, z = self.local_plan(op.plan).coords(times)
        off = self.lead.offsets.get(op.id)
        if off is not None:
            e, n, z = e + off[0], n + off[1], z + off[2]
        return LocalPlan(e, n, z, times)

    def candidate(
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
    ) -> Candidate:
        """``new`` as a candidate for ``dest``, with its lead-in. ``verify_from`` skips
        leading waypoints (an escape leg that starts inside a fence)."""
        return Candidate(
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
            lead=self.lead_in(op),
        )
