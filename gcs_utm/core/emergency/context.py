"""What EM's parts are handed: :class:`EmContext`, the one thing the action modules receive.

The :class:`~.manager.EmergencyManager` is an orchestrator: it owns the open cases and the
recommendations and dispatches each threat to a part (``single``, ``geofences``,
``immediate``, ``endpoint``, ``supervision``, ``expiry``, ``adoption``, ``closing``,
``recheck``). A part is a module of functions that take an :class:`EmContext` (named ``em``
in their signatures): the frame, the settings, TD, the measured response times, the state
they read and write (cases, recommendations), the bookkeeping every part shares (issue a
recommendation, audit, when a plan can start) and one callback, :attr:`EmContext.decide`,
for the parts that must decide a case again (supervision). No part imports the manager.
Pure: time comes from the snapshot or the caller.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.emergency.config import EmergencyConfig
from gcs_utm.core.emergency.decision import ACTOR, Case, Decision
from gcs_utm.core.emergency.lead import ResponseTimes
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    AuditEntry,
    Command,
    FlightPlan,
    Geofence,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
)

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction import TacticalDeconfliction

Decide = Callable[[Case, AirspaceSnapshot], Decision]
"""A fresh decision for an open case on the current snapshot (the manager's dispatch by
the case's action)."""

_IN_FORCE = (RecommendationState.ACCEPTED, RecommendationState.APPLIED)


def deviation_start(
    frame: LocalFrame, new: FlightPlan, old: FlightPlan, threshold_m: float
) -> float | None:
    """The first time (1 s steps) ``new`` is more than ``threshold_m`` (3D) from where
    ``old`` has the UAS at the same time; None when it never is."""
    times = np.arange(new.start_t_s, new.end_t_s + 1.0, 1.0)
    a, _ = plan_to_local(new, frame).sample(times)
    b, _ = plan_to_local(old, frame).sample(times)
    far = np.flatnonzero(np.linalg.norm(a - b, axis=1) > threshold_m)
    return float(times[far[0]]) if far.size else None


@dataclass(frozen=True, slots=True)
class EmContext:
    """The frame, settings, TD and state EM's parts work on (see the module docstring).
    ``cases`` and ``recs`` are the manager's own dicts: a part that records a
    recommendation or opens a case changes the manager's state."""

    frame: LocalFrame
    config: EmergencyConfig
    td: TacticalDeconfliction
    monitoring: MonitoringConfig
    lead: ResponseTimes
    """Measured answer, upload and command times (see .lead)."""
    cases: dict[ThreatId, Case]
    """The open cases, one per threat id."""
    recs: dict[RecommendationId, Recommendation]
    """The current version of every recommendation."""
    floors: dict[RecommendationId, int]
    """Versions of an id numbered elsewhere (another instance of a cluster): the next
    version of the id is above them."""
    decide: Decide

    # ---- state ------------------------------------------------------------------------------
    def recommendation(self, rec_id: RecommendationId) -> Recommendation | None:
        return self.recs.get(rec_id)

    def record(self, rec: Recommendation) -> Recommendation:
        """Store ``rec`` as the current version of its id; returns it."""
        self.recs[rec.id] = rec
        return rec

    def case(self, threat_id: ThreatId) -> Case | None:
        return self.cases.get(threat_id)

    def open_threats(self) -> list[ThreatId]:
        return list(self.cases)

    def pending_in(self, case: Case) -> bool:
        """Is a recommendation of ``case`` waiting for an answer?"""
        return any(self.recs[r].state is RecommendationState.PROPOSED for r in case.rec_ids)

    def in_force(self, case: Case) -> bool:
        """Is a recommendation of ``case`` accepted or applied?"""
        return any(self.recs[r].state in _IN_FORCE for r in case.rec_ids)

    def audit(self, t_s: float, action: str, subject: str, detail: dict[str, object]) -> AuditEntry:
        return AuditEntry(t_s=t_s, actor=ACTOR, action=action, subject=str(subject), detail=detail)

    # ---- timing -----------------------------------------------------------------------------
    def deadline(self, threat: Threat, now: float) -> float:
        """The answer deadline of a recommendation decided ``now``: the predicted event less
        ``deadline_margin_s``, within [``min_response_s``, ``answer_window_s``] from now."""
        event = threat.predicted_event_at_s
        if event is None:
            event = now + self.config.default_event_horizon_s
        cfg = self.config
        latest = now + max(cfg.min_response_s, cfg.answer_window_s)
        return min(latest, max(now + cfg.min_response_s, event - cfg.deadline_margin_s))

    def plan_start(self, threat: Threat, now: float) -> float:
        """When a plan decided now can start: the expected answer (none in autonomous mode;
        measured per vehicle, else the automatic operator's delay or ``expected_answer_s``,
        never past the deadline), the upload and a margin (see .lead). The vehicle has the
        plan before then, and its first waypoint lies ahead of it."""
        return self.lead.plan_start(threat.uas_ids, now, self.deadline(threat, now))

    def manoeuvre_start(self, rec: Recommendation) -> float:
        """When the plan of ``rec`` leaves the UAS's path (its lead-in ends)."""
        return self.lead.plan_start((rec.operation_id,), rec.created_t_s, rec.deadline_t_s)

    def earliest_receipt(self, now: float, op_ids: Iterable[OperationId] = ()) -> float:
        """The earliest the vehicle can have a plan decided now: an immediate answer (or the
        automatic operator's delay) plus the upload. A new plan carries timed points of the
        current path from then to its start (TD's lead-in)."""
        return self.lead.earliest_receipt(op_ids, now)

    # ---- recommendations --------------------------------------------------------------------
    def issue(
        self,
        case: Case,
        op_id: OperationId,
        now: float,
        *,
        selected: Alternative | None = None,
        command: Command | None = None,
        alternatives: Sequence[Alternative] = (),
        reason: str,
        geofence: Geofence | None = None,
    ) -> Decision:
        """A new recommendation (or a new version replacing a pending one)."""
        rid = RecommendationId(f"{case.threat.id}/{op_id}")
        prev = self.recs.get(rid)
        superseded: list[RecommendationId] = []
        recs: list[Recommendation] = []
        if prev is not None and prev.state is RecommendationState.PROPOSED:
            old = prev.transition(RecommendationState.SUPERSEDED, now, "replaced by a new version")
            recs.append(old)
            superseded.append(rid)
        op = case.operations.get(op_id)
        if selected is not None and selected.plan is not None and op is not None:
            t_dev = deviation_start(self.frame, selected.plan, op.plan, op.flight_geometry_m)
            if t_dev is not None:
                case.deviates_at[rid] = t_dev
        rec = Recommendation(
            id=rid,
            version=max(0 if prev is None else prev.version, self.floors.get(rid, 0)) + 1,
            threat_id=case.threat.id,
            threat_kind=case.threat.kind,
            operation_id=op_id,
            created_t_s=now,
            deadline_t_s=self.deadline(case.threat, now),
            selected=selected,
            command=command,
            alternatives=tuple(alternatives),
            reason=reason,
            new_geofence=geofence,
            state_t_s=now,
        )
        commands: tuple[Command, ...] = ()
        if self.config.autonomous:
            rec = rec.transition(RecommendationState.ACCEPTED, now, "autonomous mode")
            if command is not None:
                commands = (command,)
        self.recs[rid] = rec
        case.rec_ids.add(rid)
        recs.append(rec)
        return Decision(
            recommendations=tuple(recs), superseded=tuple(superseded), commands=commands
        )
