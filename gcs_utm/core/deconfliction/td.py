"""Tactical Deconfliction: alternatives, each with cost and riskiness, for EM to choose from.

:class:`TacticalDeconfliction` composes strategies that never import it: each is handed one
call's :class:`.context.Context` (frame, configurations, start time and lead-in, whether the
tracking tolerances are kept free, the shared plan cache and airborne traffic) and returns
candidates (:class:`.context.Candidate`) and drops, which :class:`.verify.Verifier` checks
and scores into alternatives. Two families (paper §4.5):

- multi-UAS loss of separation (:mod:`.multi`): charged cords (:mod:`.cords`) in several
  scenarios: a joint vertical and a joint lateral repulsion where every mobile UAS moves in
  inverse proportion to its priority (neighbours that the deformation pushes into are part of
  the problem, which resolves chains), and per involved UAS a single-mover go up / go down /
  go left / go right; plus a delay (only for a vehicle that can hover) and a speed change
  found by search (:mod:`.timing`), and keep-plan (cost 0) for every UAS;
- single UAS (:mod:`.single`, routes in :mod:`.router`): A* on a visibility graph of
  inflated geofences: reroute around a crossing, escape from inside, direct to goal, back to
  plan, next waypoint, return home, nearest reachable landing site; intruders
  (:mod:`.intruder`): vertical or lateral avoidance.

Every new plan starts at the *start time* EM passes in (when the vehicle will have the plan:
decision + expected answer + upload + margin), at the position the UAS will have then on its
plan as flown: ahead along its path, never a point it has passed. Its times come from the
vehicle's performance envelope (``Operation.performance()``: climb and descent rates, speed
range, hover or not; :mod:`.deform`). Before it is returned it is checked against that
envelope and the safety floor (:mod:`.safety`) and verified by the Monitoring core
(``plan_vs_geofences`` and ``plan_vs_plans`` against every operation outside the problem);
dropped candidates are listed in :attr:`TacticalDeconfliction.dropped` with the reason.
Compatibility between alternatives of UAS in the same problem is checked with the same
Monitoring function by :meth:`TacticalDeconfliction.compatible` during EM's joint selection.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

from gcs_utm.core.deconfliction import context as cx
from gcs_utm.core.deconfliction import loitering as lt
from gcs_utm.core.deconfliction.at_rest import at_rest
from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.context import Context, Dropped
from gcs_utm.core.deconfliction.geometry import LocalFence, LocalPlan, fence_to_local
from gcs_utm.core.deconfliction.intruder import intruder_candidates
from gcs_utm.core.deconfliction.multi import cord_candidates, dedupe
from gcs_utm.core.deconfliction.plan_cache import PlanCache
from gcs_utm.core.deconfliction.single import single_candidates
from gcs_utm.core.deconfliction.verify import Verifier
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
    Threat,
)

__all__ = ["Dropped", "TacticalDeconfliction"]


class TacticalDeconfliction:
    """Generates verified alternatives; pure apart from the :attr:`dropped` diagnostics of
    the last call and the caches it keeps between calls (local plans, airborne traffic,
    Monitoring configurations per pair minima).

    ``buffered`` (default True) keeps the vehicles' tracking tolerances free around new
    plans (:func:`.context.pair_minima`); EM passes False for a second search when no
    combination keeps them, and for the re-check before an upload."""

    def __init__(
        self, frame: LocalFrame, config: DeconflictionConfig, monitoring: MonitoringConfig
    ) -> None:
        self.frame = frame
        self.config = config
        self.monitoring = monitoring
        self.dropped: list[Dropped] = []
        self._plans = PlanCache(frame)
        self._air = lt.Airborne(config.horizon_s)  # airborne UAS hover after their plan
        self._verifier = Verifier(frame, config, monitoring, self._plans, self._air)

    def _context(
        self,
        snapshot: AirspaceSnapshot,
        start_t_s: float | None,
        lead_in_from_t_s: float | None,
        buffered: bool,
    ) -> Context:
        """One call's context: new plans start at ``start_t_s`` (never before the snapshot)
        with lead-in points from ``lead_in_from_t_s`` (see :meth:`.context.Context.lead_in`)."""
        t0 = cx.start_time(snapshot, start_t_s)
        return Context(
            frame=self.frame,
            config=self.config,
            monitoring=self.monitoring,
            plans=self._plans,
            air=self._air,
            start_t_s=t0,
            buffered=buffered,
            lead=cx.lead_in_window(lead_in_from_t_s, t0),
        )

    # ---- what EM asks besides alternatives ---------------------------------------------------
    def local_plan(self, plan: FlightPlan) -> LocalPlan:
        return self._plans.local(plan)

    def local_fences(self, geofences: Sequence[Geofence]) -> list[LocalFence]:
        return [fence_to_local(g, self.frame) for g in geofences]

    def others(
        self, snapshot: AirspaceSnapshot, exclude: Collection[OperationId]
    ) -> list[Operation]:
        """The traffic other than ``exclude``, airborne UAS after their plan (loitering.py)."""
        return lt.traffic(snapshot, exclude, self.frame, self._air.until(snapshot), cx.INACTIVE)

    def current_xyz(self, op: Operation, snapshot: AirspaceSnapshot) -> FloatArray:
        """Where the UAS is now: its track if tracked, else its plan at the snapshot time."""
        return cx.current_xyz(op, snapshot, self.frame, self._plans)

    def alt_limits(self, op: Operation) -> tuple[float, float]:
        """Altitude band a deformation stays in (:func:`.context.alt_limits`)."""
        return cx.alt_limits(op, self.frame, self.config)

    def pair_minima(
        self, a: Operation, b: Operation, *, buffered: bool = True
    ) -> tuple[float, float]:
        """(horizontal, vertical) minima TD keeps between ``a`` and ``b``
        (:func:`.context.pair_minima`)."""
        return cx.pair_minima(self.monitoring, a, b, buffered=buffered)

    def verify(
        self,
        plan: FlightPlan,
        op: Operation,
        others: Sequence[Operation],
        geofences: Sequence[Geofence],
        *,
        buffered: bool = True,
    ) -> list[str]:
        """What Monitoring would flag on ``plan`` (empty list = clean), hovering after its end
        when the UAS is airborne. With nothing to check against, Monitoring is not asked."""
        return self._verifier.verify(plan, op, others, geofences, buffered=buffered)

    def compatible(
        self, a: Alternative, b: Alternative, snapshot: AirspaceSnapshot, *, buffered: bool = True
    ) -> bool:
        """True when the plans of two alternatives (of different UAS) keep separation, as
        Monitoring checks it. An alternative without a plan (a command) is compatible."""
        return self._verifier.compatible(a, b, snapshot, buffered=buffered)

    # ---- alternatives -------------------------------------------------------------------------
    def resolve_loss_of_separation(
        self,
        threat: Threat,
        snapshot: AirspaceSnapshot,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
        *,
        buffered: bool = True,
    ) -> dict[OperationId, list[Alternative]]:
        """Alternatives per UAS of the conflict and of the neighbours drawn into it
        (:func:`.multi.cord_candidates`). Every UAS gets ``KEEP_PLAN`` (if Monitoring does
        not flag its plan against outsiders) so that EM's joint selection can leave the
        higher-priority UAS alone. New plans start at ``start_t_s``: where each UAS will be
        when it gets the plan."""
        snapshot = at_rest(snapshot, self.frame, start_t_s, lead_in_from_t_s)
        ctx = self._context(snapshot, start_t_s, lead_in_from_t_s, buffered)
        queue, out = cord_candidates(ctx, threat, snapshot)
        self.dropped = self._verifier.flush(queue, snapshot.t_s, buffered=buffered)
        return {k: dedupe(v) for k, v in out.items() if v or k in threat.uas_ids}

    def resolve_intruder(
        self,
        threat: Threat,
        operation_id: OperationId,
        snapshot: AirspaceSnapshot,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
        *,
        buffered: bool = True,
    ) -> list[Alternative]:
        """Vertical or lateral avoidance of a non-cooperative intruder (:mod:`.intruder`),
        kept only when it holds the intruder minima against the intruder's predicted path."""
        snapshot = at_rest(snapshot, self.frame, start_t_s, lead_in_from_t_s)
        ctx = self._context(snapshot, start_t_s, lead_in_from_t_s, buffered)
        got = intruder_candidates(ctx, threat, operation_id, snapshot)
        self.dropped = self._verifier.flush(got.queue, snapshot.t_s, buffered=buffered)
        kept, lost = got.kept(self.frame, ctx.start_t_s, snapshot.t_s)
        self.dropped += lost
        return kept

    def resolve_single(
        self,
        threat: Threat,
        operation_id: OperationId,
        snapshot: AirspaceSnapshot,
        maneuvers: Collection[Maneuver] | None = None,
        extra_geofences: Sequence[Geofence] = (),
        *,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
        buffered: bool = True,
    ) -> list[Alternative]:
        """Single-UAS alternatives (A*), verified (:func:`.single.single_candidates`)."""
        snapshot = at_rest(snapshot, self.frame, start_t_s, lead_in_from_t_s)
        ctx = self._context(snapshot, start_t_s, lead_in_from_t_s, buffered)
        queue, out = single_candidates(
            ctx,
            threat,
            operation_id,
            snapshot,
            maneuvers=maneuvers,
            extra_geofences=extra_geofences,
        )
        self.dropped = self._verifier.flush(queue, snapshot.t_s, buffered=buffered)
        return out
