"""EmergencyService: the asyncio side of Emergency Management.

One task (:meth:`EmergencyService.run`) takes threats and pilot answers from one bounded queue
in arrival order, asks the pure :class:`EmergencyManager` on a fresh snapshot (from the
injected provider, at the injected clock's time) and hands every :class:`Decision` to
``on_decision``. Between items it enforces recommendation deadlines on the clock: a pending
recommendation past its deadline goes to ``EmergencyManager.on_expired``, and at most every
``supervise_s`` the accepted plans are supervised (``EmergencyManager.supervise``: a threat
still predicted after its plan was applied gets a new decision).

Upload outcomes: the service is also an operator port of the USM (``present``/``update``);
when the USM reports a recommendation APPLIED or FAILED, the outcome is queued for
``EmergencyManager.on_outcome`` (a failure re-plans once, then the safe command is proposed).
Every state change also goes to ``EmergencyManager.lead`` (answer, upload and command times
measured per vehicle: how soon a new plan can start, ``gcs_utm.core.emergency.lead``).
Wire it with ``usm.attach_operator(emergency)``.

An escalation that repeats one raised less than ``emergency.escalation_window_s`` earlier (the
same UAS, cause and command) is not raised again but updates it
(``gcs_utm.core.emergency.coalesce``): a case retried every cycle no longer swamps the pilot.

Queue policy: bounded (``queue_size``); submitters wait when it is full (threats and answers
are never dropped). A failure while deciding is logged and turned into an escalation
Decision, so the operator hears about it and the loop keeps going. Cancelling ``run`` cancels
its helper tasks and returns nothing half-done (a Decision is delivered whole or not at all).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, replace

from gcs_utm.clock import Clock
from gcs_utm.core.emergency import Decision, EmergencyManager
from gcs_utm.core.emergency.coalesce import EscalationCoalescer
from gcs_utm.core.emergency.ground import not_decided, on_ground
from gcs_utm.model import (
    AirspaceSnapshot,
    Geofence,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatStatus,
)

_log = logging.getLogger(__name__)

Adoptable = tuple[Threat, Sequence[Recommendation], Sequence[Geofence]]


@dataclass(frozen=True, slots=True)
class _Answer:
    rec_id: RecommendationId
    version: int
    accepted: bool


@dataclass(frozen=True, slots=True)
class _Outcome:
    rec_id: RecommendationId
    version: int
    applied: bool
    reason: str


_Item = Threat | _Answer | _Outcome


class EmergencyService:
    def __init__(
        self,
        em: EmergencyManager,
        snapshot_provider: Callable[[float], AirspaceSnapshot],
        clock: Clock,
        on_decision: Callable[[Decision], Awaitable[None]],
        *,
        idle_s: float = 1.0,
        queue_size: int = 1000,
        supervise_s: float = 1.0,
    ) -> None:
        self.em = em
        self._snapshot = snapshot_provider
        self._clock = clock
        self._on_decision = on_decision
        self._idle_s = idle_s
        self._queue: asyncio.Queue[_Item] = asyncio.Queue(maxsize=queue_size)
        self._supervise_s = supervise_s
        self._supervised_t_s = -math.inf
        self._coalesce = EscalationCoalescer(em.config.escalation_window_s)
        self.processed = 0
        self.failures = 0
        self.adoptions: dict[ThreatId, Adoptable] = {}
        """New threat id -> the earlier life's threat it adopts (gcs_utm.services.restart_review),
        its recommendations and geofences; taken when the threat arrives."""

    async def submit_threats(self, threats: list[Threat]) -> None:
        for t in threats:
            await self._queue.put(t)

    async def submit_answer(self, rec_id: RecommendationId, version: int, accepted: bool) -> None:
        await self._queue.put(_Answer(rec_id, version, accepted))

    async def submit_outcome(
        self, rec_id: RecommendationId, version: int, applied: bool, reason: str
    ) -> None:
        await self._queue.put(_Outcome(rec_id, version, applied, reason))

    def renumber(self, rec_id: RecommendationId, version: int) -> bool:
        """A cluster member took over the prompt of ``rec_id`` as ``version`` (a number
        allocated in the shared store, gcs_utm.cluster.decisions): when that is EM's pending
        version under a smaller number, it takes ``version``, so the pilot's answer names
        EM's version and EM's next version of the id is above every stored one. Immediate
        (not queued): EM decides on one task, and this runs between its steps."""
        cur = self.em.recommendation(rec_id)
        if cur is None or cur.state is not RecommendationState.PROPOSED or cur.version >= version:
            return False
        self.em.record(replace(cur, version=version))
        return True

    def continue_after(self, rec_id: RecommendationId, version: int) -> None:
        """Versions of ``rec_id`` up to ``version`` are in the shared store (a cluster member
        gained the region of its operation): EM's next version is numbered above them."""
        self.em.continue_after(rec_id, version)

    # The USM's operator port: EM hears how accepted recommendations ended.
    async def present(self, rec: Recommendation) -> None:
        return None

    async def update(self, rec: Recommendation) -> None:
        self.em.lead.on_state(rec)  # measured answer, upload and command times (core.lead)
        if rec.state is RecommendationState.APPLIED:
            await self.submit_outcome(rec.id, rec.version, True, rec.reason)
        elif rec.state is RecommendationState.FAILED:
            await self.submit_outcome(rec.id, rec.version, False, rec.reason)

    def pending(self) -> list[Recommendation]:
        return self.em.pending()

    def plan_problem(self, rec: Recommendation) -> str:
        """Why the accepted plan of ``rec`` must not be uploaded now (core.emergency.recheck,
        on a fresh snapshot): the USM asks right before the upload."""
        return self.em.plan_problem(rec, self._snapshot(self._clock.now_s()))

    async def run(self) -> None:
        getter: asyncio.Future[_Item] | None = None
        sleeper: asyncio.Future[None] | None = None
        try:
            while True:
                await self._expire_due()
                await self._supervise_due()
                if getter is None:
                    getter = asyncio.ensure_future(self._queue.get())
                now = self._clock.now_s()
                deadlines = [r.deadline_t_s for r in self.em.pending()]
                wait_s = self._idle_s
                if deadlines:
                    wait_s = max(0.0, min(wait_s, min(deadlines) - now))
                sleeper = asyncio.ensure_future(self._clock.sleep(wait_s))
                waiters: set[asyncio.Future[object]] = {getter, sleeper}  # type: ignore[arg-type]
                await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
                if not sleeper.done():
                    sleeper.cancel()
                sleeper = None
                if getter.done():
                    item = getter.result()
                    getter = None
                    await self._process(item)
        finally:
            for fut in (getter, sleeper):
                if fut is not None and not fut.done():
                    fut.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await fut

    async def _expire_due(self) -> None:
        now = self._clock.now_s()
        due = [r for r in self.em.pending() if r.deadline_t_s <= now]
        for rec in due:

            def expire(rec: Recommendation = rec) -> Decision:
                return self.em.on_expired(rec, self._snapshot(now))

            await self._decide(expire, rec.id)

    async def _supervise_due(self) -> None:
        now = self._clock.now_s()
        if now - self._supervised_t_s < self._supervise_s or not self.em.supervising():
            return  # no snapshot is built when no accepted plan is waiting
        self._supervised_t_s = now
        await self._decide(lambda: self.em.supervise(self._snapshot(now)), "supervision")

    async def _process(self, item: _Item) -> None:
        now = self._clock.now_s()
        if isinstance(item, _Outcome):
            out = item
            await self._decide(
                lambda: self.em.on_outcome(
                    out.rec_id, out.version, out.applied, out.reason, self._snapshot(now)
                ),
                out.rec_id,
            )
        elif isinstance(item, _Answer):
            rec = self.em.recommendation(item.rec_id)
            if rec is None:
                _log.warning("answer to unknown recommendation %s ignored", item.rec_id)
                return
            asked = replace(rec, version=item.version)
            await self._decide(
                lambda: self.em.on_answer(asked, item.accepted, self._snapshot(now)), item.rec_id
            )
        elif item.status is ThreatStatus.CLOSED:  # its geofences go with it
            await self._decide(lambda: self.em.close_threat(item), item.id)
        elif (held := self.adoptions.pop(item.id, None)) is not None:
            await self._decide(lambda: self._adopt(item, held, now), item.id)
        else:
            await self._decide(lambda: self._on_threat(item, now), item.id)
        self.processed += 1

    def _adopt(self, threat: Threat, held: Adoptable, now: float) -> Decision:
        """A restart detected the condition of an earlier life's threat again: its case is
        taken over (nothing in force: decided as a new threat)."""
        inherited, recs, fences = held
        d = self.em.adopt_case(
            threat,
            inherited=inherited,
            recommendations=recs,
            geofences=fences,
            now=now,
        )
        return d if d is not None else self._on_threat(threat, now)

    def _on_threat(self, threat: Threat, now: float) -> Decision:
        """EM's decision on a threat, none for one with a UAS on the ground (ground.py)."""
        snapshot = self._snapshot(now)
        grounded = on_ground(threat, snapshot)
        if grounded:
            return not_decided(threat, grounded, now)
        return self.em.on_threat(threat, snapshot)

    async def _decide(self, step: Callable[[], Decision], subject: str) -> None:
        try:
            decision = step()
        except Exception as exc:  # a bug must reach the operator, not stop the service
            self.failures += 1
            _log.exception("emergency decision on %s failed", subject)
            decision = Decision(escalations=(f"EM failed on {subject}: {exc!r}",))
        decision = self._coalesce.apply(decision, self._clock.now_s())  # repeats: updates
        if decision != Decision():
            await self._on_decision(decision)
