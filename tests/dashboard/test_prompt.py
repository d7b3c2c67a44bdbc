"""The pilot prompt under Textual's own harness (``App.run_test`` + ``Pilot``): what is
highlighted is what gets flown, keys act only on the prompt on screen, deadlines are wall
seconds, and the prompt stays readable at 80x24."""

from __future__ import annotations

import html
import re
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from textual.app import App

from gcs_utm.clock import ManualClock
from gcs_utm.dashboard.summary import SummaryApp
from gcs_utm.dashboard.tui import DashboardApp
from gcs_utm.dashboard.view import Minima
from gcs_utm.model import (
    Alternative,
    Maneuver,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))
from test_dashboard import OP, _plan, _tracks, _usm
from usm_fakes import FakeVehicles

R1 = RecommendationId("t1/UAS1")


class FiveTimesClock(ManualClock):
    """A manual clock that says it runs 5 times faster than wall time (``--speed 5``)."""

    @property
    def speed(self) -> float:
        return 5.0


class FakeMonotonic:
    def __init__(self) -> None:
        self.t_s = 1000.0

    def __call__(self) -> float:
        return self.t_s


def _rec(
    version: int = 1, rid: RecommendationId = R1, deadline_t_s: float = 40.0
) -> Recommendation:
    def alt(m: Maneuver, cost: float, ratio: float) -> Alternative:
        return Alternative(
            operation_id=OP,
            maneuver=m,
            plan=_plan(),
            cost=cost,
            risk=0.05,
            detail=f"{m.value}: cords offset 30 m; cost={cost}, a long explanation "
            "that must wrap instead of being cut at forty characters",
            extra_length_m=42.0,
            extra_time_s=8.0,
            separation_ratio=ratio,
        )

    return Recommendation(
        id=rid,
        version=version,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=10.0,
        deadline_t_s=deadline_t_s,
        selected=alt(Maneuver.GO_LEFT, 0.254, 1.2),
        alternatives=(alt(Maneuver.GO_UP, 0.31, 1.5), alt(Maneuver.GO_DOWN, 0.4, 1.1)),
    )


def _app(usm: Usm, mono: FakeMonotonic, **kw: object) -> DashboardApp:
    app = DashboardApp(
        usm,
        _tracks,
        refresh_s=0.1,
        monotonic=mono,
        minima=Minima(horizontal_m=50.0, vertical_m=30.0),
        **kw,  # type: ignore[arg-type]
    )
    usm.attach_operator(app)
    return app


def screen_text(app: App[Any]) -> str:
    """The characters on screen, row by row (from Textual's SVG screenshot)."""
    svg = app.export_screenshot()
    rows: dict[float, list[tuple[float, str]]] = {}
    for m in re.finditer(r'<text class="[^"]*" x="([\d.]+)" y="([\d.]+)"[^>]*>(.*?)</text>', svg):
        rows.setdefault(float(m.group(2)), []).append((float(m.group(1)), m.group(3)))
    return "\n".join(
        "".join(html.unescape(t) for _, t in sorted(rows[y])).replace("\xa0", " ")
        for y in sorted(rows)
    )


async def test_highlight_then_accept_flies_the_highlighted_option() -> None:
    usm = _usm()
    vehicles = FakeVehicles()
    usm.attach_vehicles(vehicles)
    mono = FakeMonotonic()
    app = _app(usm, mono)
    async with app.run_test(size=(140, 50)) as pilot:
        await usm.on_recommendation(_rec())
        await pilot.pause()
        mono.t_s += 2.0  # read the prompt
        await pilot.press("n")  # row 1: go_up
        await pilot.pause()
        assert "[a] accept 1 go_up" in screen_text(app)
        await pilot.press("a")
        await pilot.pause()
    await usm.drain()
    record = usm.recommendations[R1]
    assert record.rec.state is RecommendationState.APPLIED
    assert record.rec.selected is not None and record.rec.selected.maneuver is Maneuver.GO_UP
    assert record.chosen == "go_up" and record.answered_via == "dashboard"
    assert len(vehicles.uploads) == 1
    assert usm.airspace.operation(OP).plan.reason.endswith("go_up")


async def test_a_key_arriving_as_the_prompt_changes_is_ignored() -> None:
    usm = _usm()
    usm.attach_vehicles(FakeVehicles())
    mono = FakeMonotonic()
    app = _app(usm, mono)
    async with app.run_test(size=(140, 50)) as pilot:
        await usm.on_recommendation(_rec(1))
        await pilot.pause()
        mono.t_s += 5.0
        # EM replaces v1 by v2 just before the pilot's key
        await usm.on_recommendation(_rec(2))
        await pilot.pause()
        mono.t_s += 0.3
        await pilot.press("a")
        await pilot.pause()
        assert app.ignored_keys == 1
        assert usm.recommendations[R1].rec.state is RecommendationState.PROPOSED
        assert "Key ignored" in screen_text(app)
        # a different recommendation takes the screen: the same rule
        mono.t_s += 2.0
        await usm.on_recommendation(_rec(1, RecommendationId("t1/UAS9")))
        await pilot.press("r")  # still v2 of R1 on screen, read for 2 s: taken
        await pilot.pause()
        assert usm.recommendations[R1].rec.state is RecommendationState.REJECTED
        await pilot.press("a")  # the prompt switched to t1/UAS9 a moment ago
        await pilot.pause()
        assert app.ignored_keys == 2
        rec9 = usm.recommendations[RecommendationId("t1/UAS9")].rec
        assert rec9.state is RecommendationState.PROPOSED


async def test_deadline_in_wall_seconds_and_warning_under_ten() -> None:
    airspace = Airspace()
    airspace.load(list(_usm().airspace.operations.values()), [])
    clock = FiveTimesClock(10.0)
    usm = Usm(airspace, clock)
    usm.threats[ThreatId("t1")] = Threat(
        id=ThreatId("t1"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=(OP, OperationId("UAS2")),
        detected_at_s=10.0,
        predicted_event_at_s=30.0,
        horizontal_m=31.0,
        vertical_m=8.0,
    )
    app = _app(usm, FakeMonotonic())
    async with app.run_test(size=(140, 50)) as pilot:
        await usm.on_recommendation(_rec(deadline_t_s=25.0))  # 15 clock s = 3 wall s
        await pilot.pause()
        text = screen_text(app)
    assert "ANSWER NOW: 3 s left (wall clock, clock x5)" in text
    assert "loss of separation with UAS2 in 4 s" in text
    assert "31 m horizontal (min 50)" in text and "8 m vertical (min 30)" in text
    assert "8 s and 42 m more flight; keeps 1.2x the minima" in text


async def test_prompt_fully_readable_at_80x24() -> None:
    usm = _usm()
    app = _app(usm, FakeMonotonic())
    async with app.run_test(size=(80, 24)) as pilot:
        await usm.on_recommendation(_rec())
        await pilot.pause()
        prompt = app.query_one("#prompt")
        assert prompt.region.y >= 1 and prompt.region.bottom <= 23  # above the footer
        assert not app.query_one("#right").display  # map and events give way to the prompt
        text = screen_text(app)
    for needed in (
        "LOSS_OF_SEPARATION",
        "recommendation t1/UAS1 v1",
        "Proposed: Turn left",
        "s left (wall clock)",
        "[a] accept 0 go_left",
        "[r] reject",
        "Climb above the plan: 8 s and 42 m more flight",  # every option in words
        "Descend below the plan",
        "Why: lowest cost and risk among 3 safe options",
    ):
        assert needed in text, (needed, text)
    # nothing of the prompt is cut: every line of the panel sits inside its border
    box = [ln for ln in text.splitlines() if ln.startswith("│")]
    assert box and all(ln.rstrip().endswith("│") for ln in box)


async def test_q_ends_the_whole_run() -> None:
    app = _app(_usm(), FakeMonotonic())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("q")
        await pilot.pause()
    assert app.quit_requested


async def test_highlight_is_kept_per_recommendation_version() -> None:
    usm = _usm()
    mono = FakeMonotonic()
    app = _app(usm, mono)
    async with app.run_test(size=(140, 50)) as pilot:
        await usm.on_recommendation(_rec())
        await pilot.press("n", "n")
        # another recommendation arriving behind this one does not move the highlight
        await usm.on_recommendation(replace(_rec(), id=RecommendationId("t1/UAS9")))
        await pilot.pause()
        assert "[a] accept 2 go_down" in screen_text(app)


@pytest.mark.parametrize(
    ("key", "last", "expected"),
    [("enter", False, True), ("q", False, False), ("enter", True, False)],
)
async def test_summary_screen_between_use_cases(key: str, last: bool, expected: bool) -> None:
    app = SummaryApp("scenario use_case_1: 2 threats", title="use_case_1 done", last=last)
    async with app.run_test(size=(80, 24)) as pilot:
        assert "scenario use_case_1: 2 threats" in screen_text(app)
        await pilot.press(key)
        await pilot.pause()
    assert app.return_value is expected


def test_a_command_proposal_names_the_command_it_accepts() -> None:
    from io import StringIO

    from rich.console import Console

    from gcs_utm.dashboard.view import collect, recommendation_panel
    from gcs_utm.model import Command, CommandKind

    rec = replace(
        _rec(),
        selected=None,
        alternatives=(),
        command=Command(kind=CommandKind.HOLD, operation_id=OP),
    )
    buf = StringIO()
    Console(file=buf, width=80, color_system=None).print(
        recommendation_panel(rec, collect(_usm(), _tracks))
    )
    text = buf.getvalue()
    assert "Proposed command: Hold at the current position" in text
    assert "[a] accept hold" in text
