"""Nothing is decided for a UAS on the ground but its pre-flight checks.

A vehicle that is disarmed, or armed and landed (``AirspaceSnapshot.grounded``, from its own
messages), has no flight to protect: a mission merely uploaded to it is timed as if it took
off at the filing, so a conflict predicted from that plan is not one (its plan is re-timed
when it takes off), and a hazard it reports is for its pilot's pre-flight checks. A threat
(other than its closing) that involves such a UAS gets no decision: no recommendation, no
mission replaced, no command, for it or for the UAS it would be paired with; the audit says
why. Once the vehicle is airborne, the threat's next update is decided as usual.
"""

from __future__ import annotations

from gcs_utm.core.emergency.decision import Decision
from gcs_utm.model import AirspaceSnapshot, AuditEntry, OperationId, Threat, ThreatStatus


def on_ground(threat: Threat, snapshot: AirspaceSnapshot) -> tuple[OperationId, ...]:
    """The UAS of ``threat`` that are on the ground (empty for a closing threat: EM closes
    its case whatever the vehicles do)."""
    if threat.status is ThreatStatus.CLOSED:
        return ()
    return tuple(u for u in threat.uas_ids if u in snapshot.grounded)


def not_decided(threat: Threat, grounded: tuple[OperationId, ...], t_s: float) -> Decision:
    """The decision for a threat with UAS on the ground: none, and an audit entry saying so."""
    who = ", ".join(grounded)
    return Decision(
        audit=(
            AuditEntry(
                t_s=t_s,
                actor="em",
                action="not_decided",
                subject=threat.id,
                detail={
                    "reason": f"{who} on the ground (pre-flight): nothing is decided for it",
                    "kind": threat.kind.value,
                    "grounded": list(grounded),
                },
            ),
        )
    )
