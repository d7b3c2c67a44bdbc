"""A fixed wing's safe hold that would circle into a geofence is replaced by a command that
does not.

When TD finds no alternative for a UAS, EM proposes the threat's safe command; for most
threats that is HOLD, and a fixed wing holds by circling round where it gets the command,
up to two turn radii from there. Beside a fence that circle crosses it: a fixed wing with a
geofence conflict and no plan out was held 108 m from the centre of a 53 m fence and flew
9 s inside it (``enc_3_0235_endpoint_crossing``, UAS3). The immediate commands
(:func:`.immediate.choose_commands`: hold, climb or descend in place, turn left or right
flying on, each checked against the fences grown by the UAS's volume) are computed for the
UAS alone; when the hold enters a fence and a command that enters none keeps the minima to
the other traffic, that command is proposed instead. Pure.
"""

from __future__ import annotations

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.immediate import Immediate, commands_now
from gcs_utm.model import AirspaceSnapshot, Command, OperationId, Threat


def _hold_fenced(tried: list[dict[str, object]], op_id: OperationId) -> bool:
    """Did the plain hold of ``op_id`` enter a fence among the combinations ``tried``?"""
    for rec in tried:
        if rec.get("commands") == {str(op_id): Immediate.HOLD.value}:
            return bool(rec.get("geofences"))
    return False


def fence_free_hold(
    em: EmContext, threat: Threat, op_id: OperationId, snapshot: AirspaceSnapshot
) -> tuple[dict[OperationId, Command], dict[OperationId, str]] | None:
    """The command (and its action's name) to propose to the fixed wing ``op_id`` instead
    of a hold whose circle enters a geofence, or None: a vehicle that can hover, a hold that
    enters no fence, or no command that enters none and keeps the minima."""
    op = snapshot.operations.get(op_id)
    if op is None or op.performance().can_hover:
        return None
    choice = commands_now(em, snapshot, [op_id], threat.predicted_event_at_s, early=False)
    if choice is None or not choice.commands or choice.geofences or not choice.clear:
        return None
    if not _hold_fenced(choice.tried, op_id):
        return None
    return choice.commands, choice.actions
