"""Headless: a prompt box only where something answers it; the stdin line prompt follows the
dashboard's binding rule; ``gcs-utm run`` without a terminal and without an answer source
refuses to start and names the flags to add."""

from __future__ import annotations

import io
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from rich.console import Console

from gcs_utm.cli import main
from gcs_utm.cli.run import demo_scenario
from gcs_utm.dashboard.headless import HeadlessView
from gcs_utm.dashboard.line import LinePrompt
from gcs_utm.model import Maneuver, RecommendationId, RecommendationState
from gcs_utm.services.usm import AnswerStatus

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))
from test_dashboard import _tracks, _usm
from test_prompt import R1, FakeMonotonic, _rec
from usm_fakes import FakeVehicles


def _console() -> tuple[Console, io.StringIO]:
    buf = io.StringIO()
    return Console(file=buf, width=100, color_system=None), buf


async def test_no_prompt_box_without_an_answer_source() -> None:
    usm = _usm()
    console, buf = _console()
    view = HeadlessView(usm, _tracks, console)
    await view.present(_rec())
    assert "[a] accept" not in buf.getvalue() and "Pilot confirmation" not in buf.getvalue()
    assert "nothing here answers it" in buf.getvalue()
    console, buf = _console()
    view = HeadlessView(usm, _tracks, console, answered_by="MQTT (remote pilot station)")
    await view.present(_rec())
    assert "answered by MQTT" in buf.getvalue() and "[a] accept" not in buf.getvalue()


async def _no_lines() -> AsyncIterator[str]:
    return
    yield ""


async def test_line_prompt_accepts_a_numbered_option_under_the_binding_rule() -> None:
    usm = _usm()
    vehicles = FakeVehicles()
    usm.attach_vehicles(vehicles)
    mono = FakeMonotonic()
    console, buf = _console()
    line = LinePrompt(usm, _tracks, console=console, lines=_no_lines, monotonic=mono)
    usm.attach_operator(line)
    await usm.on_recommendation(_rec(1))
    assert "a number + Enter" in buf.getvalue() and "Climb above the plan" in buf.getvalue()
    mono.t_s += 3.0
    await usm.on_recommendation(_rec(2))  # EM replaced the prompt just before the answer
    mono.t_s += 0.2
    assert await line.handle("2\n") is None
    assert line.ignored == 1 and "ignored '2'" in buf.getvalue()
    mono.t_s += 2.0
    assert await line.handle("x\n") is None  # not an answer: nothing happens
    outcome = await line.handle("2\n")
    await usm.drain()
    assert outcome is not None and outcome.status is AnswerStatus.ACCEPTED
    record = usm.recommendations[R1]
    assert record.rec.version == 2 and record.rec.state is RecommendationState.APPLIED
    assert record.rec.selected is not None and record.rec.selected.maneuver is Maneuver.GO_DOWN
    assert record.answered_via == "console"
    assert usm.recommendations[RecommendationId(R1)].chosen == "go_down"


async def test_line_prompt_reads_lines_from_its_source() -> None:
    usm = _usm()
    mono = FakeMonotonic()
    console, _buf = _console()

    async def typed() -> AsyncIterator[str]:
        mono.t_s += 5.0
        yield "r\n"

    line = LinePrompt(usm, _tracks, console=console, lines=typed, monotonic=mono)
    usm.attach_operator(line)
    await usm.on_recommendation(_rec(1))
    await line.run()
    assert usm.recommendations[R1].rec.state is RecommendationState.REJECTED


def test_run_without_terminal_or_answer_source_refuses(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))  # not a terminal
    code = main(["run", str(demo_scenario("use_case_1.toml")), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert "--auto-accept" in err and "--mqtt" in err
    assert not list(tmp_path.iterdir())  # refused before anything started


def test_q_in_the_first_use_case_ends_the_whole_demo(monkeypatch: pytest.MonkeyPatch) -> None:
    from gcs_utm.cli import run as run_cli

    ran: list[str] = []

    def quit_first(path: Path, args: object, **_kw: object) -> int:
        ran.append(path.name)
        return 3  # what _run_one returns when the operator pressed q

    monkeypatch.setattr(run_cli, "_run_one", quit_first)
    assert main(["demo", "--headless", "--auto-accept"]) == 0
    assert ran == ["use_case_1.toml"]
