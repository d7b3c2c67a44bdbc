"""Decisions that cross instances, carried through the shared store.

One instance decides for a threat (:mod:`gcs_utm.cluster.policy`); the UAS it decides for
may be another instance's, whose MAVLink link and pilot are there. Everything a decider
hands over goes through the store, not the MQTT exchange: the store is durable (a region
taken over after a crash still finds what was decided for it), every hand-over is a row the
audit can follow, and the decider hears the outcome from the same rows; the exchange is
QoS 0, latest-wins traffic, right for tracks and wrong for commands.

- **decider** (:meth:`DecisionRelay.file`): a recommendation for another instance's operation
  is filed in the store as a new version allocated there (:func:`gcs_utm.store.versions.
  allocate`: unique across lives, so a re-decision never collides with the owner's version);
  its EM's number is mapped to the filed one. A later state of that version is an ordinary
  write of the mapped version.
- **owner** (:meth:`DecisionRelay.take`, every refresh): the latest version another life
  filed for one of its operations is
  - PROPOSED: proposed to its pilot as a new version in its own life (upload on acceptance);
  - ACCEPTED with a command (hold, land, ... decided in autonomous mode): the command is sent
    to the vehicle at once, as a new version in its own life, then marked APPLIED or FAILED
    (the command's own audit row names the outcome); one past its deadline is stale and left.
- **decider's EM** (:meth:`DecisionRelay.relay`): hears the owner's answer (when its own
  version was still a prompt) and the outcome, in its own version numbers.
- **decider become owner** (:meth:`DecisionRelay.adopt` of a version of a recommendation this
  life's EM decided: its region was gained with the prompt pending): EM's pending version
  takes the adopted (store-allocated) number (``EmergencyPort.renumber``), so the pilot's
  answer reaches EM under the number the pilot saw, and EM's next version of the id, which
  goes to this instance's USM directly, is above every stored version. Likewise EM's next
  version of a recommendation that is not pending at the gain (e.g. accepted, its upload
  the former owner's) is numbered above the highest stored one (``continue_after``).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from typing import Protocol

from gcs_utm.clock import Clock
from gcs_utm.cluster.fence import LeaseFence
from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.model import (
    Command,
    Measurement,
    Recommendation,
    RecommendationId,
    RecommendationState,
)
from gcs_utm.store import StoreError, versions

_log = logging.getLogger(__name__)


class UsmPort(Protocol):
    async def on_recommendation(self, rec: Recommendation) -> None: ...

    async def execute_command(self, command: Command, *, reason: str = "") -> bool: ...

    def log_event(self, kind: str, text: str) -> None: ...

    def on_measurement(self, m: Measurement) -> None: ...


class EmergencyPort(Protocol):
    """What the decider's EM hears about a recommendation another instance carried out."""

    async def submit_answer(
        self, rec_id: RecommendationId, version: int, accepted: bool
    ) -> None: ...

    async def submit_outcome(
        self, rec_id: RecommendationId, version: int, applied: bool, reason: str
    ) -> None: ...

    def renumber(self, rec_id: RecommendationId, version: int) -> bool: ...

    def continue_after(self, rec_id: RecommendationId, version: int) -> None: ...


# the owner's state of its version -> what the decider's EM hears (an answer, an outcome)
_ANSWER_OF = {"accepted": True, "applied": True, "failed": True, "rejected": False}
_OUTCOME_OF = {"applied": True, "failed": False}


def is_command(rec: Recommendation) -> bool:
    """A recommendation carried out by a command (no plan to upload)."""
    return rec.command is not None and (rec.selected is None or rec.selected.plan is None)


class DecisionRelay:
    """The hand-over of decisions between this member life and the others (see module)."""

    def __init__(
        self,
        *,
        member: ClusterMember,
        policy: OwnershipPolicy,
        usm: UsmPort,
        clock: Clock,
        record: Callable[[object], None],
        fence: LeaseFence,
        emergency: EmergencyPort | None = None,
    ) -> None:
        self._member = member
        self._policy = policy
        self._usm = usm
        self._clock = clock
        self._record = record
        self._fence = fence
        self._emergency = emergency
        self._filed: dict[tuple[str, int], int] = {}  # (id, EM's version) -> filed version
        self._em_of: dict[tuple[str, int], int] = {}  # (id, filed version) -> EM's version
        self.adopted: set[tuple[str, int]] = set()  # versions of other lives taken here
        self._relayed: set[tuple[str, int, str]] = set()

    async def _allocate(self, rec: Recommendation) -> int:
        epoch, fence = self._member.epoch, self._fence
        got = await self._member.read(lambda s: versions.allocate(s, rec, epoch, fence))
        assert isinstance(got, int)
        return got

    # ---- decider ------------------------------------------------------------------------
    async def file(self, rec: Recommendation) -> None:
        """File an EM decision for another instance's operation (see module)."""
        key = (str(rec.id), rec.version)
        filed = self._filed.get(key)
        if filed is not None:  # a later state of a version filed here
            self._record(dataclasses.replace(rec, version=filed))
            return
        try:
            filed = await self._allocate(rec)
        except StoreError as exc:
            _log.warning("cluster: %s v%d not filed: %s", rec.id, rec.version, exc)
            self._usm.log_event("cluster", f"{rec.id} v{rec.version} not filed: {exc}")
            return
        self._filed[key] = filed
        self._em_of[(str(rec.id), filed)] = rec.version
        renumbered = "" if filed == rec.version else f" (EM's v{rec.version})"
        self._usm.log_event(
            "cluster",
            f"{rec.id} v{filed}{renumbered} {rec.state.value}: filed for "
            f"{rec.operation_id}'s owner",
        )

    async def relay(self, touched: list[tuple[str, int, str, int]]) -> None:
        """Tell this instance's EM what the owner did with a recommendation it decided for
        the owner's operation: the owner's later version accepted (or rejected), then applied
        (or failed). Without it the EM would let its own version expire and decide again."""
        if self._emergency is None:
            return
        mine: dict[str, tuple[int, str]] = {}
        later: dict[str, tuple[int, str]] = {}
        for rec_id, version, state, epoch in touched:
            if epoch == self._member.epoch:
                mine[rec_id] = (version, state)
                later.pop(rec_id, None)
            elif rec_id in mine:
                later[rec_id] = (version, state)
        for rec_id, (version, state) in later.items():
            ours, our_state = mine[rec_id]
            em_version = self._em_of.get((rec_id, ours), ours)
            await self._tell(rec_id, em_version, our_state, version, state)

    async def _tell(
        self, rec_id: str, em_version: int, our_state: str, version: int, state: str
    ) -> None:
        assert self._emergency is not None
        rid = RecommendationId(rec_id)
        answer = _ANSWER_OF.get(state)
        # an answer only to a prompt: a version born accepted (autonomous) needs none
        if (
            answer is not None
            and our_state == RecommendationState.PROPOSED.value
            and (rec_id, em_version, "answer") not in self._relayed
        ):
            self._relayed.add((rec_id, em_version, "answer"))
            await self._emergency.submit_answer(rid, em_version, answer)
        outcome = _OUTCOME_OF.get(state)
        if outcome is not None and (rec_id, em_version, "outcome") not in self._relayed:
            self._relayed.add((rec_id, em_version, "outcome"))
            await self._emergency.submit_outcome(
                rid, em_version, outcome, f"{state} by its owner as v{version}"
            )

    # ---- owner --------------------------------------------------------------------------
    async def adopt(self, rec: Recommendation, reason: str) -> None:
        """Propose ``rec`` (another life's version) to this instance's pilot as a new version
        allocated in this life."""
        self.adopted.add((str(rec.id), rec.version))
        mine = dataclasses.replace(rec, version=rec.version + 1, reason=reason)
        try:
            version = await self._allocate(mine)
        except StoreError as exc:
            _log.warning("cluster: %s v%d not adopted: %s", rec.id, rec.version, exc)
            self._usm.log_event("cluster", f"{rec.id} v{rec.version} not adopted: {exc}")
            return
        # this life's EM decided it (for an operation that was foreign here, now gained):
        # its pending version continues from the adopted number (see module)
        if self._emergency is not None and self._emergency.renumber(rec.id, version):
            self._usm.log_event("cluster", f"{rec.id}: EM's pending version is now v{version}")
        await self._usm.on_recommendation(dataclasses.replace(mine, version=version))

    def continue_after(self, highest: tuple[tuple[str, int], ...]) -> None:
        """A region was gained: EM's next version of each of these recommendations (of the
        region's operations) is numbered above the highest stored one (see module)."""
        if self._emergency is not None:
            for rec_id, version in highest:
                self._emergency.continue_after(RecommendationId(rec_id), version)

    async def take(self, open_recs: list[tuple[Recommendation, int]]) -> None:
        """The prompts and commands other lives filed for this instance's operations."""
        for rec, epoch in open_recs:
            if epoch == self._member.epoch or not self._policy.owns(rec.operation_id):
                continue
            if (str(rec.id), rec.version) in self.adopted:
                continue
            if rec.state is RecommendationState.PROPOSED:
                self._usm.log_event("cluster", f"{rec.id} v{rec.version} decided by life {epoch}")
                await self.adopt(rec, f"decided by life {epoch}, proposed by {self._member.holder}")
            elif is_command(rec) and rec.deadline_t_s > self._clock.now_s():
                await self.carry_out(rec, epoch)

    async def carry_out(self, rec: Recommendation, epoch: int) -> None:
        """Send the command of ``rec`` (decided and accepted by life ``epoch``) to the
        vehicle, as a new version in this life, and file its outcome."""
        assert rec.command is not None
        self.adopted.add((str(rec.id), rec.version))
        kind = rec.command.kind.value
        mine = dataclasses.replace(
            rec,
            version=rec.version + 1,
            reason=f"{kind} decided by life {epoch}, sent by {self._member.holder}",
        )
        try:
            version = await self._allocate(mine)
        except StoreError as exc:
            _log.warning("cluster: %s v%d not carried out: %s", rec.id, rec.version, exc)
            self._usm.log_event("cluster", f"{rec.id} v{rec.version} not carried out: {exc}")
            return
        mine = dataclasses.replace(mine, version=version)
        self._usm.log_event(
            "cluster", f"{rec.id} v{version}: {kind} for {rec.operation_id} from life {epoch}"
        )
        ok = await self._usm.execute_command(
            rec.command, reason=f"recommendation {rec.id} v{version} (decided by life {epoch})"
        )
        state = RecommendationState.APPLIED if ok else RecommendationState.FAILED
        why = "command acknowledged" if ok else "command not acknowledged"
        self._record(mine.transition(state, self._clock.now_s(), why))


__all__ = ["DecisionRelay", "EmergencyPort", "UsmPort", "is_command"]
