"""Why Monitoring closes a threat: the words that go with the CLOSED threat (its message ends
``; closed: <reason>``, as the USM's closing of a hazard's threat does) so that the operator
and EM's audit see why it is over. Pure: reads the snapshot only.
"""

from __future__ import annotations

from collections.abc import Sequence

from gcs_utm.model import AirspaceSnapshot, OperationId, OperationState, Threat


def over_reason(
    op_ids: Sequence[str], intruder_id: str | None, snapshot: AirspaceSnapshot
) -> str | None:
    """Why a threat of ``op_ids`` (and of the non-cooperative track ``intruder_id``) is over
    whatever the figures say, or None while all of them still fly: an operation gone from the
    snapshot, landed or ended, a vehicle on the ground by its own messages (not traffic), or
    the intruder's track dropped (tracking drops one silent for ``intruder_drop_after_s``) or
    on the ground (an unfiled MAVLink vehicle that landed)."""
    for u in op_ids:
        o = snapshot.operations.get(OperationId(u))
        if o is None:
            return f"operation {u} is gone"
        if o.state in (OperationState.LANDED, OperationState.ENDED):
            return f"operation {u} {o.state.value}"
        if o.id in snapshot.grounded:
            return f"{u} is on the ground"
    if intruder_id is not None and intruder_id not in snapshot.tracks:
        return f"intruder {intruder_id} is no longer tracked"
    if intruder_id is not None and intruder_id in snapshot.grounded_tracks:
        return f"intruder {intruder_id} is on the ground"
    return None


def clear_reason(close_cycles: int) -> str:
    """A threat whose condition has been clear by the margin for ``close_cycles`` cycles."""
    return f"clear by the margin for {close_cycles} cycles"


def closed_message(threat: Threat, reason: str) -> str:
    """The message of ``threat`` once closed for ``reason``."""
    return f"{threat.message}; closed: {reason}" if threat.message else f"closed: {reason}"
