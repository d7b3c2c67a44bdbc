"""The command proposed for a UAS whose plan failed twice: for a loss of separation EM's
immediate command, chosen against all traffic, not a bare hold.

A plan that fails its upload or the re-check before it (:mod:`.recheck`) is re-planned
once; the second failure escalates and proposes a safe command (:mod:`.supervision`). For a
loss of separation that was the threat's safe command, a hold where the UAS is, checked
against nothing: the multirotor UAS2 of ``enc_8_0233_late_vertical``, whose way round UAS5
was refused twice before its upload (as flown late at its corners, too close to UAS1), was
held at 88 s 25 m beside the path of the fixed wing UAS6, 33 m above it (minima 50 / 40 m),
and UAS6 passed it at 41.3 m / 33.1 m at 98 s. For a loss of separation the proposal is now
the immediate command (:func:`.immediate.propose`: hold, climb or descend in place, checked
against every UAS, the one that limits it commanded too, or flying on when every command
separates less), as for an unanswered recommendation (:mod:`.expiry`). Other threats keep
their safe command (land, return to launch, hold). Pure.
"""

from __future__ import annotations

from collections.abc import Sequence

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.core.emergency.immediate import propose
from gcs_utm.core.emergency.supervision import escalate_safe
from gcs_utm.model import AirspaceSnapshot, OperationId, ThreatKind


def after_failure(
    em: EmContext, case: Case, op_ids: Sequence[OperationId], snapshot: AirspaceSnapshot, why: str
) -> Decision:
    """Escalate with ``why`` and propose, for ``op_ids`` of ``case``, the immediate command of
    a loss of separation (see the module doc), else the threat's safe command."""
    if case.threat.kind is ThreatKind.LOSS_OF_SEPARATION:
        return propose(em, case, snapshot, why, list(op_ids))
    return escalate_safe(em, case, list(op_ids), snapshot.t_s, why)
