"""The interactive dashboard (Textual, built on rich): live tables and the pilot prompt.

The app is also an operator port of the USM: when a recommendation arrives it is queued and
shown; single keys answer it through ``Usm.answer`` exactly like an MQTT answer would.

Binding rule (what a key acts on):
- ``a`` accepts the highlighted option (``n``/``p`` move the highlight; row 0 is the proposed
  option) of exactly the recommendation id and version on screen when the key was pressed;
- a key arriving while the prompt differs from what is on screen, or within ``guard_s`` wall
  seconds after the prompt changed (a new version, a different recommendation), is ignored and
  the prompt says so: the pilot reads the new prompt and presses again;
- the USM refuses an answer to a version that is no longer proposed or past its deadline.

Operator commands (:mod:`gcs_utm.dashboard.commands`): ``u`` picks the UAS, ``h``/``l``/``t``/``m``
arm hold / land / return to launch / resume for it, ``y`` or the same key again confirms and
``Esc`` cancels; the command line above the footer shows the selection, the question and the
outcome.

Deadlines are shown in wall-clock seconds (the clock's seconds divided by its speed) and
counted down at every refresh; under 10 s the prompt turns red. A recommendation that expires
unanswered raises an alarm (:mod:`.alarm`): a red banner naming it (in the title of the next
prompt, EM's re-proposal, while one is shown), a notification and the terminal bell. ``d``
shows or hides the raw scores.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import ClassVar

from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.events import Resize
from textual.widgets import Footer, Header, Static

from gcs_utm.dashboard.airspace_map import map_legend
from gcs_utm.dashboard.airspace_scene import scene_of
from gcs_utm.dashboard.alarm import ExpiryAlarms
from gcs_utm.dashboard.commands import KEYS, CommandKeys
from gcs_utm.dashboard.panels import geofences_panel
from gcs_utm.dashboard.view import (
    DashboardData,
    Minima,
    collect,
    operations_table,
    recommendation_panel,
    threats_table,
)
from gcs_utm.dashboard.widgets import AirspaceMap, EventLog
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import Recommendation, RecommendationId, RecommendationState, Track, TrackId
from gcs_utm.services.recommendations import alternative_index_of_row, options_of
from gcs_utm.services.usm import AnswerOutcome, Usm

_log = logging.getLogger(__name__)

NARROW_COLUMNS = 100
"""Below this width the map and event columns are hidden while a prompt is shown."""

_Key = tuple[RecommendationId, int]


class DashboardApp(App[None]):
    """Live airspace picture with the accept/reject prompt."""

    CSS = """
    #top { height: 1fr; min-height: 3; }
    #left { width: 2fr; }
    #right { width: 1fr; }
    #prompt { height: auto; }
    #alarm { height: auto; background: red; color: white; text-style: bold; }
    #command { height: auto; max-height: 2; }
    #map { height: auto; min-height: 8; max-height: 65%; }
    #events { height: 1fr; min-height: 3; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("a", "accept", "Accept highlighted"),
        Binding("r", "reject", "Reject"),
        Binding("n", "next_alternative", "Next option"),
        Binding("p", "prev_alternative", "Prev option"),
        Binding("d", "details", "Scores"),
        Binding("tab", "next_pending", "Next pending"),
        Binding("u", "select_uas", "UAS"),
        *(
            Binding(k, f"command('{k}')", c.upper() if c == "rtl" else c.title())
            for k, c in KEYS.items()
        ),
        Binding("y", "confirm_command", "Yes", show=False),
        Binding("escape", "cancel_command", "No", show=False),
        Binding("q", "quit", "Quit"),
    ]

    def __init__(
        self,
        usm: Usm,
        tracks: Callable[[], dict[TrackId, Track]],
        *,
        operator: str = "dashboard",
        refresh_s: float = 0.5,
        minima: Minima | None = None,
        guard_s: float = 1.0,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self._usm = usm
        self._tracks = tracks
        self._operator = operator
        self._refresh_s = refresh_s
        self._minima = minima
        self._guard_s = guard_s
        self._monotonic = monotonic
        self._queue: list[RecommendationId] = []
        self._highlight: dict[_Key, int] = {}
        self._shown: _Key | None = None
        self._shown_at = -float("inf")
        self._note = ""
        self.outcomes: list[AnswerOutcome] = []
        self.ignored_keys = 0
        self.quit_requested = False
        self._mounted_once = False
        self.alarms = ExpiryAlarms()
        self._details = False
        self.commands = CommandKeys(
            usm, operator=operator, monotonic=monotonic, on_done=self._refresh_view
        )

    # ---- OperatorPort ----------------------------------------------------------------------
    async def present(self, rec: Recommendation) -> None:
        if rec.id not in self._queue:
            self._queue.append(rec.id)
        if line := self.alarms.proposed(rec, self._monotonic()):
            self._alarm(line)
        self._refresh_view()

    async def update(self, rec: Recommendation) -> None:
        if rec.state is not RecommendationState.PROPOSED and rec.id in self._queue:
            self._queue.remove(rec.id)
        if rec.state is RecommendationState.EXPIRED:
            self._alarm(self.alarms.expired(rec, self._monotonic()))
        self._refresh_view()

    def _alarm(self, line: str) -> None:
        """Make an expiry impossible to miss: bell, notification (the banner is drawn by
        the refresh)."""
        if self._mounted_once:
            self.bell()
            self.notify(line, severity="error", timeout=10.0)

    # ---- layout ------------------------------------------------------------------------------
    def compose(self) -> ComposeResult:
        yield Header(show_clock=False)
        with Horizontal(id="top"):
            with Vertical(id="left"):
                yield Static(id="operations")
                yield Static(id="threats")
                yield Static(id="geofences")
            with Vertical(id="right"):
                yield AirspaceMap(id="map")
                yield Static(id="legend")
                yield EventLog(id="events")
        yield Static(id="alarm")
        yield Static(id="prompt")
        yield Static(id="command")
        yield Footer()

    def on_mount(self) -> None:
        self.title = "gcs-utm"
        self._mounted_once = True
        self.set_interval(self._refresh_s, self._refresh_view)
        self._refresh_view()

    def on_resize(self, _event: Resize) -> None:
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

    def _row(self, rec: Recommendation) -> int:
        n = max(1, len(options_of(rec)))
        return self._highlight.get((rec.id, rec.version), 0) % n

    def _render_all(self) -> None:
        d = collect(self._usm, self._tracks, self._minima)
        width = self.size.width
        rec = self._current(d)
        key = None if rec is None else (rec.id, rec.version)
        if key != self._shown:
            self._shown = key
            self._shown_at = self._monotonic()
        narrow = width < NARROW_COLUMNS
        right = self.query_one("#right")
        right.display = not (narrow and rec is not None)
        self.query_one("#operations", Static).update(
            operations_table(d, width=width * 2 // 3 if right.display else width)
        )
        self.query_one("#threats", Static).update(threats_table(d))
        self.query_one("#geofences", Static).update(geofences_panel(d))
        if right.display:
            scene = scene_of(d)
            self.query_one("#map", AirspaceMap).show(scene)
            self.query_one("#legend", Static).update(map_legend(scene, right.size.width))
            self.query_one("#events", EventLog).show(d.events, d.t_s)
        self.query_one("#command", Static).update(self.commands.line())
        # the alarm in full when no prompt is up; with a prompt (the re-proposal), in its
        # title: the prompt keeps its room at 80x24
        now_wall_s = self._monotonic()
        alarm = self.query_one("#alarm", Static)
        alarm.update(self.alarms.current(now_wall_s))
        alarm.display = rec is None and bool(self.alarms.current(now_wall_s))
        prompt = self.query_one("#prompt", Static)
        if rec is None:
            prompt.update("")
            prompt.display = False
            return
        prompt.display = True
        prompt.update(
            recommendation_panel(
                rec,
                d,
                viewing=self._row(rec),
                queue=len(self._queue),
                note=self._note,
                details=self._details,
                alarm=self.alarms.short(now_wall_s),
            )
        )

    # ---- actions -----------------------------------------------------------------------------
    def _ignore(self, why: str) -> None:
        self.ignored_keys += 1
        self._note = f"Key ignored: {why}. Read the prompt and press again."
        self.notify(self._note, severity="warning")
        self._refresh_view()

    async def _answer(self, decision: PilotDecision) -> None:
        d = collect(self._usm, self._tracks, self._minima)
        rec = self._current(d)
        if rec is None:
            self.bell()
            return
        if (rec.id, rec.version) != self._shown:
            self._ignore(f"the prompt changed to {rec.id} v{rec.version}")
            return
        if self._monotonic() - self._shown_at < self._guard_s:
            self._ignore(f"the prompt changed less than {self._guard_s:g} s ago")
            return
        row = self._row(rec)
        index = alternative_index_of_row(rec, row) if decision is PilotDecision.ACCEPT else None
        self._note = ""
        outcome = await self._usm.answer(
            PilotAnswer(
                recommendation_id=rec.id,
                version=rec.version,
                decision=decision,
                t_s=self._usm.clock.now_s(),
                operator=self._operator,
                source="dashboard",
                alternative_index=index,
            )
        )
        self.outcomes.append(outcome)
        self.alarms.acknowledge()
        if outcome.reason:
            self.notify(f"{rec.id} v{rec.version}: {outcome.status.value} ({outcome.reason})")
        self._refresh_view()

    async def action_accept(self) -> None:
        await self._answer(PilotDecision.ACCEPT)

    async def action_reject(self) -> None:
        await self._answer(PilotDecision.REJECT)

    def _move(self, step: int) -> None:
        d = collect(self._usm, self._tracks, self._minima)
        rec = self._current(d)
        if rec is None:
            return
        n = max(1, len(options_of(rec)))
        self._highlight[(rec.id, rec.version)] = (self._row(rec) + step) % n
        self._refresh_view()

    def action_next_alternative(self) -> None:
        self._move(1)

    def action_prev_alternative(self) -> None:
        self._move(-1)

    def action_details(self) -> None:
        """Show or hide the raw scores (cost, risk, scoring terms) under the words."""
        self._details = not self._details
        self._refresh_view()

    def action_next_pending(self) -> None:
        if len(self._queue) > 1:
            self._queue.append(self._queue.pop(0))
        self._refresh_view()

    # ---- operator commands (gcs_utm.dashboard.commands) ----------------------------------------
    def action_select_uas(self) -> None:
        self.commands.select_next()
        self._refresh_view()

    def action_command(self, key: str) -> None:
        self.commands.press(key)
        self._refresh_view()

    def action_confirm_command(self) -> None:
        if not self.commands.confirm():
            self.bell()
        self._refresh_view()

    def action_cancel_command(self) -> None:
        self.commands.cancel()
        self._refresh_view()

    async def action_quit(self) -> None:
        """End the whole run (``gcs-utm demo`` does not start its next use case)."""
        self.quit_requested = True
        self.exit()
