"""``--headless``: no TUI; the picture and every recommendation as rich log lines on a console
(stderr by default), for unattended runs and CI logs."""

from __future__ import annotations

from collections.abc import Callable

from rich.console import Console

from gcs_utm.dashboard.view import collect, headless_line, recommendation_panel
from gcs_utm.model import Recommendation, Track, TrackId
from gcs_utm.services.usm import Usm


class HeadlessView:
    """An operator port that only shows (answers come from ``--auto-*`` or MQTT)."""

    def __init__(
        self,
        usm: Usm,
        tracks: Callable[[], dict[TrackId, Track]],
        console: Console | None = None,
    ) -> None:
        self._usm = usm
        self._tracks = tracks
        self.console = console or Console(stderr=True, width=110)

    async def present(self, rec: Recommendation) -> None:
        d = collect(self._usm, self._tracks)
        self.console.print(recommendation_panel(rec, d, queue=len(d.pending)))

    async def update(self, rec: Recommendation) -> None:
        self.console.log(f"recommendation {rec.id} v{rec.version}: {rec.state.value} {rec.reason}")

    def status(self) -> None:
        self.console.log(headless_line(collect(self._usm, self._tracks)))
