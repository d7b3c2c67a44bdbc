"""Neighbours whose vehicle is not heard: traffic to keep clear of, never to re-plan.

The cord problem (:mod:`.multi`) draws into a loss of separation the operations whose plans
come near the involved ones, and may deform them too. An operation filed ahead of its flight
whose vehicle is not heard yet (no fresh track) cannot take a new plan: the upload fails ("no
vehicle heard on any link"), EM re-plans once, proposes the safe command, that fails too,
and the case ends in an escalation with nothing to propose (enc_7_0009_late_near_threshold:
a loss at 44 s re-planned a fixed wing that appeared at 94 s). Such a neighbour keeps its
plan, a constraint the others are deformed around. A snapshot in which the involved UAS have
no track either is one of plans alone (a benchmark, a what-if): every neighbour is taken by
its plan there, as before. Pure."""

from __future__ import annotations

from collections.abc import Sequence

from gcs_utm.model import AirspaceSnapshot, Operation, OperationId


def unheard(
    snapshot: AirspaceSnapshot, involved: Sequence[Operation], neighbours: Sequence[Operation]
) -> set[OperationId]:
    """The ``neighbours`` without a fresh track in ``snapshot`` when every ``involved`` UAS
    has one (else none: a snapshot of plans alone)."""
    heard = {tr.operation_id for tr in snapshot.tracks.values() if not tr.stale}
    if not all(op.id in heard for op in involved):
        return set()
    return {op.id for op in neighbours if op.id not in heard}
