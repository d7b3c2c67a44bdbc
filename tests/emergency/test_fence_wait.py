"""A predicted geofence entry with no feasible alternative yet is decided again before the
safe command while the entry is far ahead: a fixed wing held 60 s before a fence circled
into a multirotor (enc_1_0036_fence_head_on). Once the entry is within the lead plus
IMMINENT_S, the safe command is proposed as before."""

from __future__ import annotations

from collections.abc import Collection, Sequence

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import EmergencyConfig, EmergencyManager
from gcs_utm.core.emergency.fence_wait import RETRY_S
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    CommandKind,
    Geofence,
    GeofenceId,
    Maneuver,
    OperationId,
    RecommendationState,
    Threat,
    ThreatKind,
)

MON = MonitoringConfig()


class _NoPath(TacticalDeconfliction):
    """TD that finds no feasible single-UAS alternative (every path blocked)."""

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
    ) -> list[Alternative]:
        return []


def test_a_far_fence_entry_without_an_alternative_waits_then_gets_the_safe_command() -> None:
    op = sc.make_operation("A", [(0, 0, 100), (3000, 0, 100)])
    snap = sc.snapshot([op], [sc.cylinder("F", 1500.0, 0.0, 50.0)])
    em = EmergencyManager(
        sc.FRAME, EmergencyConfig(), _NoPath(sc.FRAME, DeconflictionConfig(), MON), MON
    )
    t = sc.threat(
        ThreatKind.GEOFENCE_CONFLICT,
        ["A"],
        t_s=snap.t_s,
        event_in_s=60.0,
        geofence_id=GeofenceId("F"),
    )
    d = em.on_threat(t, snap)
    assert d.recommendations == () and d.escalations == ()
    assert d.warnings and "decided again" in d.warnings[0]
    assert em.supervise(snap).recommendations == ()  # nothing before the retry is due
    # decided again within RETRY_S: still far, still waiting
    later = AirspaceSnapshot(
        t_s=snap.t_s + RETRY_S, operations=snap.operations, tracks={}, geofences=snap.geofences
    )
    assert em.supervise(later).warnings
    # once the entry is near, the safe command is proposed with the escalation
    near = AirspaceSnapshot(
        t_s=snap.t_s + 55.0, operations=snap.operations, tracks={}, geofences=snap.geofences
    )
    d = em.supervise(near)
    assert d.escalations
    (rec,) = [r for r in d.recommendations if r.state is RecommendationState.PROPOSED]
    assert rec.command is not None and rec.command.kind is CommandKind.HOLD
