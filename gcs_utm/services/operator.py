"""Operators that answer recommendations without a person: ``--auto-accept`` and
``--auto-reject`` for scripted runs and tests. They answer through the USM exactly like the
dashboard or MQTT would, after an optional think time (clock seconds)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable

from gcs_utm.clock import Clock
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import Recommendation, RecommendationState

_log = logging.getLogger(__name__)


class AutoOperator:
    """Answers every proposed recommendation with ``decision`` after ``delay_s``.

    ``reject_first`` > 0 rejects that many proposals before accepting (to exercise the
    re-planning path: a rejected recommendation must lead to a different one)."""

    def __init__(
        self,
        answer: Callable[[PilotAnswer], Awaitable[object]],
        clock: Clock,
        *,
        decision: PilotDecision = PilotDecision.ACCEPT,
        delay_s: float = 1.0,
        reject_first: int = 0,
        name: str = "auto",
    ) -> None:
        self._answer = answer
        self._clock = clock
        self._decision = decision
        self._delay_s = delay_s
        self._reject_left = reject_first
        self._name = name
        self._tasks: set[asyncio.Task[None]] = set()
        self.answered: list[tuple[str, int, PilotDecision]] = []

    async def present(self, rec: Recommendation) -> None:
        task = asyncio.ensure_future(self._answer_later(rec))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def update(self, rec: Recommendation) -> None:
        return None

    async def _answer_later(self, rec: Recommendation) -> None:
        await self._clock.sleep(self._delay_s)
        if rec.state is not RecommendationState.PROPOSED:
            return
        decision = self._decision
        if self._reject_left > 0:
            self._reject_left -= 1
            decision = PilotDecision.REJECT
        self.answered.append((rec.id, rec.version, decision))
        await self._answer(
            PilotAnswer(
                recommendation_id=rec.id,
                version=rec.version,
                decision=decision,
                t_s=self._clock.now_s(),
                operator=self._name,
                source="auto",
            )
        )
