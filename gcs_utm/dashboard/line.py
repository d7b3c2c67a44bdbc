"""The headless line prompt: recommendations printed on a console, answered by typing a line
on stdin (``a`` accept the proposed option, a number accept that option, ``r`` reject, ``details``
the raw scores, then Enter). Used by ``--headless`` runs whose stdin is a terminal. Operator
commands are typed there too: ``hold UAS1`` (``land``, ``rtl``, ``resume``), then ``y`` to
send it (:class:`gcs_utm.dashboard.commands.LineCommands`).

A recommendation that expires unanswered is a loud ``!!! EXPIRED ...`` line (with the
terminal bell), and its re-proposal another one (:mod:`.alarm`).

The binding rule is the dashboard's: a line acts on the recommendation id and version printed
last; a line arriving after a different prompt replaced it, or within ``guard_s`` wall seconds
of a new prompt, is ignored and the console says so.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
import time
from collections.abc import AsyncIterator, Callable

from rich.console import Console

from gcs_utm.dashboard.alarm import ExpiryAlarms
from gcs_utm.dashboard.commands import LINE_HELP, LineCommands
from gcs_utm.dashboard.view import Minima, collect, recommendation_panel
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import Recommendation, RecommendationId, RecommendationState, Track, TrackId
from gcs_utm.services.recommendations import alternative_index_of_row, options_of
from gcs_utm.services.usm import AnswerOutcome, Usm

LINE_KEYS = (
    "type a + Enter: accept 0   a number + Enter: accept that option   r + Enter: reject   "
    "details + Enter: scores"
)


async def stdin_lines() -> AsyncIterator[str]:
    """Lines typed on stdin, read without blocking the event loop."""
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    transport, _ = await loop.connect_read_pipe(
        lambda: asyncio.StreamReaderProtocol(reader), sys.stdin
    )
    try:
        while line := await reader.readline():
            yield line.decode(errors="replace")
    finally:
        transport.close()
        with contextlib.suppress(OSError, ValueError):
            os.set_blocking(sys.stdin.fileno(), True)  # leave the terminal as it was


class LinePrompt:
    """An operator port printing prompts and taking answers line by line."""

    def __init__(
        self,
        usm: Usm,
        tracks: Callable[[], dict[TrackId, Track]],
        *,
        console: Console | None = None,
        lines: Callable[[], AsyncIterator[str]] = stdin_lines,
        operator: str = "console",
        minima: Minima | None = None,
        guard_s: float = 1.0,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self._usm = usm
        self._tracks = tracks
        self._lines = lines
        self._operator = operator
        self._minima = minima
        self._guard_s = guard_s
        self._monotonic = monotonic
        self.console = console or Console(stderr=True, width=110)
        self._shown: tuple[RecommendationId, int] | None = None
        self._shown_at = -float("inf")
        self.outcomes: list[AnswerOutcome] = []
        self.ignored = 0
        self.alarms = ExpiryAlarms()
        self.commands = LineCommands(
            usm,
            operator=operator,
            source="console",
            write=lambda text: self.console.print(text, markup=False, highlight=False),
        )

    def _current(self) -> Recommendation | None:
        pending = sorted(self._usm.pending(), key=lambda r: r.deadline_t_s)
        return pending[0] if pending else None

    def _show(self) -> None:
        """Print the prompt when the one to answer changed."""
        rec = self._current()
        key = None if rec is None else (rec.id, rec.version)
        if key == self._shown:
            return
        self._shown = key
        self._shown_at = self._monotonic()
        if rec is not None:
            d = collect(self._usm, self._tracks, self._minima)
            self.console.print(recommendation_panel(rec, d, queue=len(d.pending), keys=LINE_KEYS))

    async def present(self, rec: Recommendation) -> None:
        if line := self.alarms.proposed(rec, self._monotonic()):
            self._loud(line)
        self._show()

    async def update(self, rec: Recommendation) -> None:
        if rec.state is RecommendationState.EXPIRED:
            self._loud(self.alarms.expired(rec, self._monotonic()))
        elif rec.state is not RecommendationState.PROPOSED:
            self.console.print(f"{rec.id} v{rec.version}: {rec.state.value} {rec.reason}")
        self._show()

    def _loud(self, line: str) -> None:
        self.console.bell()
        self.console.print(line, style="bold white on red", markup=False)

    def _details(self, text: str) -> bool:
        """``details`` (or ``d``): the prompt again with the raw scores (cost, risk, scoring
        terms). False for any other line."""
        if text not in ("d", "details"):
            return False
        rec = self._current()
        if rec is None:
            self.console.print("nothing to answer")
            return True
        d = collect(self._usm, self._tracks, self._minima)
        self.console.print(
            recommendation_panel(rec, d, queue=len(d.pending), keys=LINE_KEYS, details=True)
        )
        return True

    async def run(self) -> None:
        """Read answers until stdin closes (or cancelled)."""
        self.console.print(f"operator commands: {LINE_HELP}")
        async for line in self._lines():
            await self.handle(line)

    async def handle(self, line: str) -> AnswerOutcome | None:
        """One typed line: answer the prompt printed last, under the binding rule."""
        text = line.strip().lower()
        if self.commands.handle(line.strip()) or not text or self._details(text):
            return None
        rec = self._current()
        if rec is None:
            self.console.print("nothing to answer")
            return None
        if (rec.id, rec.version) != self._shown or (
            self._monotonic() - self._shown_at < self._guard_s
        ):
            self.ignored += 1
            self._show()
            self.console.print(
                f"[bold magenta]ignored {text!r}: the prompt changed to {rec.id} "
                f"v{rec.version}; read it and answer again[/]"
            )
            return None
        decision = PilotDecision.REJECT if text in ("r", "reject") else PilotDecision.ACCEPT
        index = None
        if decision is PilotDecision.ACCEPT:
            row = 0 if text in ("a", "accept") else None
            if row is None and text.isdigit() and int(text) < max(1, len(options_of(rec))):
                row = int(text)
            if row is None:
                self.console.print(f"not an answer: {text!r} ({LINE_KEYS})")
                return None
            index = alternative_index_of_row(rec, row)
        outcome = await self._usm.answer(
            PilotAnswer(
                recommendation_id=rec.id,
                version=rec.version,
                decision=decision,
                t_s=self._usm.clock.now_s(),
                operator=self._operator,
                source="console",
                alternative_index=index,
            )
        )
        self.outcomes.append(outcome)
        self.console.print(
            f"{rec.id} v{rec.version}: {decision.value} {outcome.status.value}"
            + (f" ({outcome.reason})" if outcome.reason else "")
        )
        self._show()
        return outcome
