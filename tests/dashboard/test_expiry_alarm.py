"""An expired recommendation is impossible to miss (Textual's own harness and the line
prompt): a red banner naming it, the bell and a notification; EM's re-proposal of the safe
command is announced on the banner and shown as the new prompt; the audit records the expiry
and the re-proposal."""

from __future__ import annotations

import sys
from dataclasses import replace
from io import StringIO
from pathlib import Path

from rich.console import Console

from gcs_utm.clock import ManualClock
from gcs_utm.dashboard.headless import HeadlessView
from gcs_utm.dashboard.line import LinePrompt
from gcs_utm.dashboard.tui import DashboardApp
from gcs_utm.dashboard.view import Minima
from gcs_utm.model import AuditEntry, Command, CommandKind, RecommendationState
from gcs_utm.services.usm import Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_dashboard import OP, _tracks, _usm
from test_prompt import R1, FakeMonotonic, _rec, screen_text

REPROPOSAL = "t1/UAS1 v1 (UAS1) expired without an answer: safe command proposed again"


def _usm_recording() -> tuple[Usm, list[object]]:
    records: list[object] = []
    return Usm(_usm().airspace, ManualClock(10.0), record=records.append), records


def _hold(version: int = 2) -> object:
    return replace(
        _rec(version, deadline_t_s=45.0),
        selected=None,
        alternatives=(),
        command=Command(kind=CommandKind.HOLD, operation_id=OP),
        reason=REPROPOSAL,
    )


def _audit(records: list[object]) -> list[tuple[str, object, object]]:
    return [
        (r.action, r.detail.get("version"), r.detail.get("proposed"))
        for r in records
        if isinstance(r, AuditEntry) and r.actor == "usm"
    ]


async def test_an_expiry_raises_the_alarm_then_the_reproposal_is_shown_and_audited() -> None:
    usm, records = _usm_recording()
    mono = FakeMonotonic()
    app = DashboardApp(
        usm,
        _tracks,
        refresh_s=0.1,
        monotonic=mono,
        minima=Minima(horizontal_m=50.0, vertical_m=30.0),
    )
    usm.attach_operator(app)
    bells: list[int] = []
    app.bell = lambda: bells.append(1)  # type: ignore[method-assign]
    async with app.run_test(size=(140, 50)) as pilot:
        await usm.on_recommendation(_rec(deadline_t_s=25.0))
        await pilot.pause()
        assert "Pilot confirmation: 15 s left" in screen_text(app)
        assert not app.query_one("#alarm").display
        usm.clock.advance(16.0)  # type: ignore[attr-defined]
        await usm.expire_due()  # nobody answered
        await pilot.pause()
        text = " ".join(screen_text(app).split())  # the banner wraps
        assert usm.recommendations[R1].rec.state is RecommendationState.EXPIRED
        assert app.query_one("#alarm").display and bells == [1]
        assert "!!! EXPIRED t1/UAS1 v1 (UAS1): nobody answered in time" in text
        assert "nothing was sent to it" in text  # what happens now
        # EM's fallback: the safe command proposed again, announced and prompted
        mono.t_s += 1.0
        await usm.on_recommendation(_hold())  # type: ignore[arg-type]
        await pilot.pause()
        text = " ".join(screen_text(app).split())  # the banner wraps
        assert "!!! EXPIRED t1/UAS1 v1: nobody answered" in text  # heads the new prompt
        assert "Proposed command: Hold at the current position" in text
        assert bells == [1, 1]
        assert app.alarms.current(mono.t_s).endswith(
            "v2 proposed instead: Hold at the current position (brake and hover; a fixed wing "
            "circles); answer it now"
        )
        # the banner stays up until answered (or 30 s without news)
        mono.t_s += 2.0
        await pilot.press("a")
        await pilot.pause()
        assert not app.query_one("#alarm").display
        assert "!!! EXPIRED" not in screen_text(app)
    audit = _audit(records)
    assert [(action, version) for action, version, _ in audit] == [
        ("recommendation_expired", 1),
        ("reproposed_after_expiry", 2),
    ]
    assert str(audit[0][2]).startswith("Turn left: 8 s and 42 m more flight")
    assert str(audit[1][2]).startswith("Hold at the current position")


async def test_the_line_prompt_shows_words_and_a_loud_expiry() -> None:
    usm, _records = _usm_recording()
    buf = StringIO()
    line = LinePrompt(
        usm,
        _tracks,
        console=Console(file=buf, width=200, color_system=None),
        monotonic=FakeMonotonic(),
    )
    usm.attach_operator(line)
    await usm.on_recommendation(_rec(deadline_t_s=25.0))
    out = buf.getvalue()
    assert "Turn left" in out and "Climb above the plan: 8 s and 42 m more flight" in out
    assert "0.254" not in out  # the raw scores only on request
    await line.handle("details\n")
    assert "0.254" in buf.getvalue() and "cords offset 30 m" in buf.getvalue()
    usm.clock.advance(16.0)  # type: ignore[attr-defined]
    await usm.expire_due()
    assert "!!! EXPIRED t1/UAS1 v1 (UAS1): nobody answered in time (Turn left" in buf.getvalue()
    await usm.on_recommendation(_hold())  # type: ignore[arg-type]
    assert (
        "!!! t1/UAS1 v2 proposed instead of expired v1: Hold at the current position"
        in buf.getvalue()
    )


async def test_at_80x24_the_alarm_heads_the_reproposal_and_the_prompt_fits() -> None:
    usm, _records = _usm_recording()
    mono = FakeMonotonic()
    app = DashboardApp(usm, _tracks, refresh_s=0.1, monotonic=mono)
    usm.attach_operator(app)
    async with app.run_test(size=(80, 24)) as pilot:
        await usm.on_recommendation(_rec(deadline_t_s=25.0))
        usm.clock.advance(16.0)  # type: ignore[attr-defined]
        await usm.expire_due()
        await pilot.pause()
        assert app.query_one("#alarm").display  # nothing else to show: the full banner
        mono.t_s += 1.0
        await usm.on_recommendation(_rec(2, deadline_t_s=45.0))  # re-planned (replan)
        await pilot.pause()
        prompt = app.query_one("#prompt")
        assert prompt.region.bottom <= 23  # above the footer, border included
        text = screen_text(app)
    assert "!!! EXPIRED t1/UAS1 v1: nobody answered" in text
    assert "recommendation t1/UAS1 v2" in text and "[a] accept 0 go_left" in text


async def test_the_headless_view_prints_a_loud_expiry() -> None:
    usm, _records = _usm_recording()
    buf = StringIO()
    view = HeadlessView(usm, _tracks, Console(file=buf, width=200, color_system=None))
    usm.attach_operator(view)
    await usm.on_recommendation(_rec(deadline_t_s=25.0))
    usm.clock.advance(16.0)  # type: ignore[attr-defined]
    await usm.expire_due()
    await usm.on_recommendation(_hold())  # type: ignore[arg-type]
    out = buf.getvalue()
    assert "!!! EXPIRED t1/UAS1 v1 (UAS1): nobody answered in time (Turn left" in out
    assert "!!! t1/UAS1 v2 proposed instead of expired v1: Hold at the current position" in out
