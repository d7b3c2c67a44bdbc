"""Who decides what in a cluster: the ownership rule every instance applies the same way.

An instance *owns* the operations in its airspace that are not *foreign*; foreign operations
are those of other instances that it watches because their UAS are in the halo of one of its
regions (:mod:`gcs_utm.cluster.exchange`). Monitoring sees both, so a conflict across a
border is detected on both sides; then:

- **one decider per threat**: a threat is decided by the owner of its most important UAS:
  the highest ``priority``; equal priorities, the smallest operation id. Both instances read
  the operations from the same store, so both reach the same answer, and the other instance
  drops the threat (it sees the decision in the store);
- a threat about foreign UAS only (their conformance, their geofences) is their owner's;
- a recommendation the decider makes for a foreign operation is filed in the store and not
  presented here: the operation's owner proposes it to its pilot as the next version in its
  own life and uploads it; a command decided for it (autonomous mode) is sent by its owner
  (:mod:`gcs_utm.cluster.decisions`);
- **no act without a live lease**: ``may_act`` (set by the cluster node: no held region past
  its local lease deadline, and the instance not fenced out) is checked before every
  threat is filed or decided, every decision is carried out and every command or plan
  reaches a vehicle (:mod:`gcs_utm.cluster.selffence`). A stale owner waking from a stall
  files nothing and commands nothing for a region that may be another instance's by then.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping

from gcs_utm.messages import HazardReport
from gcs_utm.model import Operation, OperationId, Recommendation, Threat


class OwnershipPolicy:
    """The rule above over the airspace's operations (``operations_of``, set by the cluster
    node once the runtime exists) and the set of foreign ones."""

    def __init__(self) -> None:
        self.operations_of: Callable[[], Mapping[OperationId, Operation]] = dict
        self.foreign: set[OperationId] = set()
        # how a decision for a foreign operation is filed for its owner (set by the cluster
        # node: gcs_utm.cluster.decisions.DecisionRelay.file); None: the plain store write
        self.filer: Callable[[Recommendation], Awaitable[None]] | None = None
        # False while this instance may not act for its regions (see module); the cluster
        # node sets it
        self.may_act: Callable[[], bool] = lambda: True
        self.dropped_stale = 0  # threats, hazards and decisions dropped for want of a lease

    def owns(self, op_id: OperationId) -> bool:
        return op_id not in self.foreign and op_id in self.operations_of()

    def decider_of(
        self, uas_ids: tuple[OperationId, ...], ops: Mapping[OperationId, Operation]
    ) -> OperationId | None:
        """The operation whose owner decides for these UAS (None when none is known)."""
        known = [ops[i] for i in uas_ids if i in ops]
        if not known:
            return None
        return min(known, key=lambda op: (-op.priority, op.id)).id

    def filter_threats(self, threats: list[Threat]) -> list[Threat]:
        """The threats this instance decides for (a threat naming no operation, a hazard of
        the service itself, is always kept)."""
        if not self.may_act():
            self.dropped_stale += len(threats)
            return []
        if not self.foreign:
            return threats
        ops = self.operations_of()
        kept = []
        for t in threats:
            decider = self.decider_of(t.uas_ids, ops) if t.uas_ids else None
            if not t.uas_ids or (decider is not None and decider not in self.foreign):
                kept.append(t)
        return kept

    def admits_hazard(self, h: HazardReport) -> bool:
        """A hazard (a lost link, a degraded GNSS, ...) becomes a threat here only while this
        instance may act, and not for a foreign operation (its owner raises it)."""
        if not self.may_act():
            self.dropped_stale += 1
            return False
        return h.operation_id is None or h.operation_id not in self.foreign


__all__ = ["OwnershipPolicy"]
