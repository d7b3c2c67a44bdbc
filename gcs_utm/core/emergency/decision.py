"""What Emergency Management decides (:class:`Decision`) and the state of one open case
(:class:`Case`), shared by the manager and its action modules."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from gcs_utm.core.emergency.config import Action
from gcs_utm.model import (
    AuditEntry,
    Command,
    Geofence,
    GeofenceId,
    Maneuver,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    Threat,
)

ACTOR = "EM"

REROUTE_MANEUVERS = frozenset(
    {
        Maneuver.REROUTE,
        Maneuver.ESCAPE,
        Maneuver.HOLD,  # offered from inside a geofence only: leave it and hold outside
        Maneuver.DIRECT_TO_GOAL,
        Maneuver.BACK_TO_PLAN,
        Maneuver.NEXT_WAYPOINT,
        Maneuver.RETURN_HOME,
        Maneuver.LANDING_SITE,
    }
)
SINGLE_MANEUVERS: dict[Action, frozenset[Maneuver]] = {
    Action.REROUTE: REROUTE_MANEUVERS,
    Action.BACK_TO_PLAN: frozenset({Maneuver.BACK_TO_PLAN, Maneuver.NEXT_WAYPOINT}),
    Action.LAND_OR_HOME: frozenset({Maneuver.LANDING_SITE, Maneuver.RETURN_HOME}),
}
"""The actions decided one UAS at a time from TD's single-UAS alternatives, and which."""
ONE_SHOT = frozenset(
    {
        Action.WARN,
        Action.SUSPEND_AND_GEOFENCE,
        Action.ALERT_AND_GEOFENCE,
        Action.GEOFENCE_FROM_AREA,
    }
)
"""Actions done once per threat: repeating them would only duplicate warnings/geofences."""


class Mode(Enum):
    """How a UAS of a case was last decided, so what a re-plan after a refusal does again."""

    MULTI = "multi"  # jointly with the other UAS of the case (charged cords)
    INTRUDER = "intruder"  # avoidance of the case's intruder
    COMMAND = "command"  # a command (immediate, safe, suspend): refused, it escalates
    SINGLE = "single"  # alone, from TD's manoeuvres in Case.maneuvers


@dataclass(frozen=True, slots=True, kw_only=True)
class Decision:
    """What one EM step asks the rest of the system to do."""

    recommendations: tuple[Recommendation, ...] = ()
    geofences: tuple[Geofence, ...] = ()
    commands: tuple[Command, ...] = ()
    escalations: tuple[str, ...] = ()
    superseded: tuple[RecommendationId, ...] = ()
    audit: tuple[AuditEntry, ...] = ()
    warnings: tuple[str, ...] = ()
    removed_geofences: tuple[GeofenceId, ...] = ()
    """Geofences EM created that are to go (their threat closed)."""

    def merge(self, other: Decision) -> Decision:
        return Decision(
            recommendations=self.recommendations + other.recommendations,
            geofences=self.geofences + other.geofences,
            commands=self.commands + other.commands,
            escalations=self.escalations + other.escalations,
            superseded=self.superseded + other.superseded,
            audit=self.audit + other.audit,
            warnings=self.warnings + other.warnings,
            removed_geofences=self.removed_geofences + other.removed_geofences,
        )


@dataclass(slots=True)
class Case:
    """One open threat: what EM did and may still do about it. ``failures`` counts failed
    uploads per UAS; ``supervised`` counts re-plans after an applied plan left the threat
    open."""

    threat: Threat
    action: Action
    attempt_t_s: float
    modes: dict[OperationId, Mode] = field(default_factory=dict)
    maneuvers: dict[OperationId, frozenset[Maneuver]] = field(default_factory=dict)
    """The manoeuvres offered to a UAS decided alone (:attr:`Mode.SINGLE`)."""
    excluded: dict[OperationId, set[Maneuver]] = field(default_factory=dict)
    replans: dict[OperationId, int] = field(default_factory=dict)
    geofences: list[Geofence] = field(default_factory=list)
    rec_ids: set[RecommendationId] = field(default_factory=set)
    failures: dict[OperationId, int] = field(default_factory=dict)
    supervised: int = 0
    operations: dict[OperationId, Operation] = field(default_factory=dict)
    """The operations as they were at the last decision (their plans then)."""
    off_plan_escalated: bool = False
    """The "plans clear, tracks predict a loss" warning was given (once per case)."""
    deviates_at: dict[RecommendationId, float] = field(default_factory=dict)
    """When each recommended plan first leaves the plan it replaces (see .supervision)."""
    final_in_force: bool = False
    """A final safe command (land, return to launch) is in force for every UAS of the case:
    supervision has stopped re-proposing it (see .supervision)."""
