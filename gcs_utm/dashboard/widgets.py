"""Thin Textual widgets over the pure renderers: each keeps the last data it was shown and
draws it at the size the layout gives it (so the map fits its box at any terminal size)."""

from __future__ import annotations

from collections.abc import Sequence

from rich.console import RenderableType
from textual.geometry import Size
from textual.widget import Widget

from gcs_utm.dashboard.airspace_map import render_map, rows_to_fit
from gcs_utm.dashboard.airspace_scene import MapScene
from gcs_utm.dashboard.panels import event_log
from gcs_utm.services.usm import UsmEvent


class AirspaceMap(Widget):
    """The airspace map (:func:`gcs_utm.dashboard.airspace_map.render_map`). With ``height:
    auto`` it asks for the rows the scene needs at its width (:func:`rows_to_fit`), so a
    flat scene leaves the rows below to the event log; ``max-height`` caps a tall one. The
    rows asked for change only when the need moves by more than one row (a track wandering
    at the edge of the scene does not make the layout jump; the map fits the rows it has)."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.scene = MapScene()
        self._rows = 0
        self._rows_width = -1

    def show(self, scene: MapScene) -> None:
        first = not self.scene.points()  # the empty map before the first snapshot
        self.scene = scene
        need = rows_to_fit(scene, self.size.width)
        jump = abs(need - self._rows) > 1 or (first and need != self._rows)
        relayout = self._rows_width == self.size.width and jump
        if relayout:
            self._rows = need
        self.refresh(layout=relayout)

    def get_content_height(self, container: Size, viewport: Size, width: int) -> int:
        if width != self._rows_width:  # first layout or a resize: ask afresh
            self._rows, self._rows_width = rows_to_fit(self.scene, width), width
        return self._rows

    def render(self) -> RenderableType:
        return render_map(self.scene, self.size.width, self.size.height).to_text()


class EventLog(Widget):
    """The event log, newest at the bottom, wrapped at words
    (:func:`gcs_utm.dashboard.panels.event_log`)."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.events: Sequence[UsmEvent] = ()
        self.now_s = 0.0

    def show(self, events: Sequence[UsmEvent], now_s: float) -> None:
        self.events, self.now_s = events, now_s
        self.refresh()

    def render(self) -> RenderableType:
        return event_log(self.events, self.now_s, self.size.width, self.size.height)
