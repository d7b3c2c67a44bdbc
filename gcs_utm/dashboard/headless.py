"""``--headless``: no TUI; the picture and every recommendation as rich log lines on a console
(stderr by default), for unattended runs and CI logs.

A prompt box is printed only where something answers it: ``answered_by`` names the answer
source (``--auto-accept``, MQTT, the line prompt); without one a recommendation is one log
line, never a box with keys that do nothing. An expiry is a loud ``!!! EXPIRED ...`` line
(:mod:`.alarm`), and so is the re-proposal that follows it.
"""

from __future__ import annotations

from collections.abc import Callable

from rich.console import Console

from gcs_utm.core.emergency.wording import proposal_text
from gcs_utm.dashboard.alarm import ExpiryAlarms
from gcs_utm.dashboard.view import Minima, collect, headless_line, recommendation_panel
from gcs_utm.model import Recommendation, RecommendationState, Track, TrackId
from gcs_utm.services.usm import Usm


class HeadlessView:
    """An operator port that only shows (answers come from ``--auto-*``, MQTT or the line
    prompt, named by ``answered_by``)."""

    def __init__(
        self,
        usm: Usm,
        tracks: Callable[[], dict[TrackId, Track]],
        console: Console | None = None,
        *,
        answered_by: str = "",
        minima: Minima | None = None,
    ) -> None:
        self._usm = usm
        self._tracks = tracks
        self._answered_by = answered_by
        self._minima = minima
        self.console = console or Console(stderr=True, width=110)
        self.alarms = ExpiryAlarms()

    async def present(self, rec: Recommendation) -> None:
        d = collect(self._usm, self._tracks, self._minima)
        if line := self.alarms.proposed(rec, d.t_s):
            self.console.print(line, style="bold white on red", markup=False)
        if not self._answered_by:
            self.console.log(
                f"recommendation {rec.id} v{rec.version} for {rec.operation_id}: "
                f"{proposal_text(rec)} (nothing here answers it)",
                markup=False,
            )
            return
        self.console.print(
            recommendation_panel(
                rec, d, queue=len(d.pending), keys=f"answered by {self._answered_by}"
            )
        )

    async def update(self, rec: Recommendation) -> None:
        if rec.state is RecommendationState.EXPIRED:
            line = self.alarms.expired(rec, self._usm.clock.now_s())
            self.console.print(line, style="bold white on red", markup=False)
            return
        self.console.log(f"recommendation {rec.id} v{rec.version} {rec.state.value} {rec.reason}")

    def status(self) -> None:
        self.console.log(headless_line(collect(self._usm, self._tracks)))
