"""The interactive dashboard (Textual, built on rich): live tables and the pilot prompt.

The app is also an operator port of the USM: when a recommendation arrives it is queued and
shown; single keys answer it through ``Usm.answer`` exactly like an MQTT answer would. The
deadline is shown counting down and enforced by the USM (a late answer is refused).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import ClassVar

from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.widgets import Footer, Header, Static

from gcs_utm.dashboard.view import (
    DashboardData,
    collect,
    events_text,
    geofences_table,
    operations_table,
    recommendation_panel,
    threats_table,
    top_view,
)
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import Recommendation, RecommendationId, RecommendationState, Track, TrackId
from gcs_utm.services.usm import AnswerOutcome, Usm

_log = logging.getLogger(__name__)


class DashboardApp(App[None]):
    """Live airspace picture with the accept/reject prompt."""

    CSS = """
    #top { height: 1fr; }
    #left { width: 2fr; }
    #right { width: 1fr; }
    #prompt { height: auto; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("a", "accept", "Accept"),
        Binding("r", "reject", "Reject"),
        Binding("n", "next_alternative", "Next option"),
        Binding("p", "prev_alternative", "Prev option"),
        Binding("tab", "next_pending", "Next pending"),
        Binding("q", "quit", "Quit"),
    ]

    def __init__(
        self,
        usm: Usm,
        tracks: Callable[[], dict[TrackId, Track]],
        *,
        operator: str = "dashboard",
        refresh_s: float = 0.5,
    ) -> None:
        super().__init__()
        self._usm = usm
        self._tracks = tracks
        self._operator = operator
        self._refresh_s = refresh_s
        self._queue: list[RecommendationId] = []
        self._viewing = 0
        self.outcomes: list[AnswerOutcome] = []
        self._mounted_once = False

    # ---- OperatorPort ----------------------------------------------------------------------
    async def present(self, rec: Recommendation) -> None:
        if rec.id not in self._queue:
            self._queue.append(rec.id)
        self._viewing = 0
        self._refresh_view()

    async def update(self, rec: Recommendation) -> None:
        if rec.state is not RecommendationState.PROPOSED and rec.id in self._queue:
            self._queue.remove(rec.id)
            self._viewing = 0
        self._refresh_view()

    # ---- layout ------------------------------------------------------------------------------
    def compose(self) -> ComposeResult:
        yield Header(show_clock=False)
        with Horizontal(id="top"):
            with Vertical(id="left"):
                yield Static(id="operations")
                yield Static(id="threats")
                yield Static(id="geofences")
            with Vertical(id="right"):
                yield Static(id="map")
                yield Static(id="events")
        yield Static(id="prompt")
        yield Footer()

    def on_mount(self) -> None:
        self.title = "gcs-utm"
        self._mounted_once = True
        self.set_interval(self._refresh_s, self._refresh_view)
        self._refresh_view()

    def _current(self, d: DashboardData) -> Recommendation | None:
        pending = {r.id: r for r in d.pending}
        self._queue = [rid for rid in self._queue if rid in pending]
        for rid in pending:
            if rid not in self._queue:
                self._queue.append(rid)
        return pending[self._queue[0]] if self._queue else None

    def _refresh_view(self) -> None:
        if not self._mounted_once or not self.screen.is_attached:
            return
        try:
            self._render_all()
        except NoMatches:  # the app is shutting down: its widgets are gone
            return

    def _render_all(self) -> None:
        d = collect(self._usm, self._tracks)
        self.query_one("#operations", Static).update(operations_table(d))
        self.query_one("#threats", Static).update(threats_table(d))
        self.query_one("#geofences", Static).update(geofences_table(d))
        self.query_one("#map", Static).update(top_view(d, width=44, height=14))
        self.query_one("#events", Static).update(events_text(d))
        rec = self._current(d)
        prompt = self.query_one("#prompt", Static)
        if rec is None:
            prompt.update("")
        else:
            prompt.update(
                recommendation_panel(rec, d, viewing=self._viewing, queue=len(self._queue))
            )

    # ---- actions -----------------------------------------------------------------------------
    async def _answer(self, decision: PilotDecision) -> None:
        d = collect(self._usm, self._tracks)
        rec = self._current(d)
        if rec is None:
            self.bell()
            return
        outcome = await self._usm.answer(
            PilotAnswer(
                recommendation_id=rec.id,
                version=rec.version,
                decision=decision,
                t_s=self._usm.clock.now_s(),
                operator=self._operator,
                source="dashboard",
            )
        )
        self.outcomes.append(outcome)
        if outcome.reason:
            self.notify(f"{rec.id}: {outcome.status.value} ({outcome.reason})")
        self._refresh_view()

    async def action_accept(self) -> None:
        await self._answer(PilotDecision.ACCEPT)

    async def action_reject(self) -> None:
        await self._answer(PilotDecision.REJECT)

    def action_next_alternative(self) -> None:
        self._viewing += 1
        d = collect(self._usm, self._tracks)
        rec = self._current(d)
        n = (1 if rec and rec.selected else 0) + (len(rec.alternatives) if rec else 0)
        if n:
            self._viewing %= n
        self._refresh_view()

    def action_prev_alternative(self) -> None:
        self._viewing = max(0, self._viewing - 1)
        self._refresh_view()

    def action_next_pending(self) -> None:
        if len(self._queue) > 1:
            self._queue.append(self._queue.pop(0))
            self._viewing = 0
        self._refresh_view()
