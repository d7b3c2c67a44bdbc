"""The summary screen of a scenario run in the TUI: shown between the demo's use cases and at
its end; Enter goes on, ``q`` ends the demo."""

from __future__ import annotations

from typing import ClassVar

from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import VerticalScroll
from textual.widgets import Footer, Header, Static


class SummaryApp(App[bool]):
    """Shows ``text``; returns True (Enter: go on) or False (``q``: stop)."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("enter", "next", "Next use case"),
        Binding("q", "stop", "Quit"),
    ]

    def __init__(self, text: str, *, title: str, last: bool = False) -> None:
        super().__init__()
        self._text = text
        self._title = title
        self._last = last

    def compose(self) -> ComposeResult:
        yield Header(show_clock=False)
        with VerticalScroll():
            yield Static(self._text, markup=False)
            hint = "Enter or q: end" if self._last else "Enter: next use case   q: end the demo"
            yield Static(f"\n{hint}")
        yield Footer()

    def on_mount(self) -> None:
        self.title = self._title

    def action_next(self) -> None:
        self.exit(not self._last)

    def action_stop(self) -> None:
        self.exit(False)
