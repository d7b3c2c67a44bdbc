"""What Emergency Management decides (:class:`Decision`) and the state of one open case
(:class:`Case`), shared by the manager and its action modules."""

from __future__ import annotations

from dataclasses import dataclass, field

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
SINGLE_MANEUVERS: dict[str, frozenset[Maneuver]] = {
    "reroute": REROUTE_MANEUVERS,
    "back_to_plan": frozenset({Maneuver.BACK_TO_PLAN, Maneuver.NEXT_WAYPOINT}),
    "land_or_home": frozenset({Maneuver.LANDING_SITE, Maneuver.RETURN_HOME}),
}
ONE_SHOT = frozenset({"warn", "suspend_and_geofence", "alert_and_geofence", "geofence_from_area"})
"""Actions done once per threat: repeating them would only duplicate warnings/geofences."""
MODE_MULTI = "multi"
MODE_INTRUDER = "intruder"
MODE_COMMAND = "command"


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
    action: str
    attempt_t_s: float
    modes: dict[OperationId, str] = field(default_factory=dict)
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
