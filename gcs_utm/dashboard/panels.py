"""Dashboard panels that size themselves: the event log wrapped to its column and the
geofence panel that folds to one line when there is nothing to list.

Pure functions of the snapshot and a size, rendered by the thin widgets of
:mod:`gcs_utm.dashboard.widgets` and testable without a terminal.
"""

from __future__ import annotations

from collections.abc import Sequence

from rich.cells import cell_len
from rich.console import RenderableType
from rich.text import Text

from gcs_utm.dashboard.view import DashboardData, geofences_table
from gcs_utm.services.usm import UsmEvent

NO_GEOFENCES = "no geofences active"

EVENT_INDENT = "  "
"""Continuation lines of a wrapped event start with this (a hanging indent)."""

STYLE_TIME = "dim"
STYLE_KIND = "cyan"


def geofences_panel(d: DashboardData) -> RenderableType:
    """The active geofences as a table, or one dim line saying there are none."""
    if not d.geofences:
        return Text(f"Geofences: {NO_GEOFENCES}", style="dim")
    return geofences_table(d)


def _words(e: UsmEvent, now_s: float) -> list[tuple[str, str]]:
    """An event as (word, style) pairs: its age in seconds, its kind, then its text."""
    return [
        (f"{e.t_s - now_s:+.0f}s", STYLE_TIME),
        (e.kind, STYLE_KIND),
        *((w, "") for w in e.text.split()),
    ]


def _pieces(words: list[tuple[str, str]], width: int) -> list[tuple[str, str]]:
    """``words`` with every word longer than a continuation line cut into line-long pieces
    (the one case where a word must break: it cannot fit on any line)."""
    room = max(1, width - len(EVENT_INDENT))
    out: list[tuple[str, str]] = []
    for word, style in words:
        out += [(word[i : i + room], style) for i in range(0, len(word), room)]
    return out


def _wrap(words: list[tuple[str, str]], width: int) -> list[Text]:
    """Greedy word wrap to ``width`` terminal cells with a hanging indent: lines break between
    words only (see :func:`_pieces` for words longer than a line)."""
    lines: list[Text] = []
    line = Text()
    for word, style in _pieces(words, width):
        started = bool(line.plain.strip())
        if started and line.cell_len + 1 + cell_len(word) > width:
            lines.append(line)
            line, started = Text(EVENT_INDENT), False
        line.append(" " if started else "")
        line.append(word, style=style or None)
    if line.plain.strip():
        lines.append(line)
    return lines


def event_log(events: Sequence[UsmEvent], now_s: float, width: int, height: int) -> Text:
    """The newest events that fit ``height`` rows of ``width`` cells, oldest at the top and
    the newest on the last line, each wrapped at word boundaries. An older event that does
    not fit whole is left out rather than cut; the newest is shown even if it alone is too
    long (its beginning)."""
    width = max(8, width)
    kept: list[list[Text]] = []
    used = 0
    for e in reversed(events):
        lines = _wrap(_words(e, now_s), width)
        if kept and used + len(lines) > height:
            break
        kept.append(lines)
        used += len(lines)
    flat = [line for lines in reversed(kept) for line in lines][: max(1, height)]
    return Text("\n").join(flat) if flat else Text("no events yet", style="dim")
