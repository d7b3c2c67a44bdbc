"""Fast time (``gcs-utm run --speed max``): the UTM and the built-in vehicles share one
simulated clock on an event loop whose time jumps to the next timer as soon as nothing is
left to compute; MAVLink still goes over loopback UDP. A run is deterministic (the same report
twice, wall-clock fields aside) and takes seconds."""

from __future__ import annotations

import asyncio
import json
import math
import socket
import time
from pathlib import Path

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario, run_scenario_blocking
from gcs_utm.cli import main
from gcs_utm.clock import FastTimeLoop, LoopClock
from gcs_utm.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"


def _options(out: Path) -> RunOptions:
    return RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=out,
        figures=False,
    )


def test_loop_time_jumps_to_the_next_timer() -> None:
    async def main_() -> tuple[float, float]:
        loop = asyncio.get_running_loop()
        clock = LoopClock(loop, 1000.0)
        await clock.sleep(3600.0)
        return clock.now_s(), clock.elapsed_s()

    wall0 = time.perf_counter()
    with asyncio.Runner(loop_factory=FastTimeLoop) as runner:
        now_s, elapsed_s = runner.run(main_())
    assert (now_s, elapsed_s) == (4600.0, 3600.0)
    assert time.perf_counter() - wall0 < 1.0


def test_a_loopback_datagram_is_read_before_time_moves_on() -> None:
    """A datagram sent now is handled at the same loop time, before any later timer."""

    async def main_() -> list[tuple[str, float]]:
        loop = asyncio.get_running_loop()
        events: list[tuple[str, float]] = []
        rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        rx.bind(("127.0.0.1", 0))
        rx.setblocking(False)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        got = asyncio.Event()

        def readable() -> None:
            rx.recv(100)
            events.append(("datagram", loop.time()))
            got.set()

        loop.add_reader(rx.fileno(), readable)
        loop.call_later(0.001, lambda: events.append(("timer", loop.time())))
        await asyncio.sleep(5.0)
        sent_at = loop.time()
        tx.sendto(b"x", rx.getsockname())
        loop.call_later(0.001, lambda: events.append(("timer", loop.time())))
        await got.wait()
        await asyncio.sleep(1.0)
        loop.remove_reader(rx.fileno())
        rx.close()
        tx.close()
        assert sent_at == 5.0
        return events

    with asyncio.Runner(loop_factory=FastTimeLoop) as runner:
        events = runner.run(main_())
    assert events == [("timer", 0.001), ("datagram", 5.0), ("timer", 5.001)]


def test_use_case_1_fast_time_is_deterministic_and_quick(tmp_path: Path) -> None:
    cpu0_s = time.process_time()
    first = run_scenario_blocking(SCENARIOS / "use_case_1.toml", Settings(), _options(tmp_path))
    cpu_s = time.process_time() - cpu0_s
    second = run_scenario_blocking(
        SCENARIOS / "use_case_1.toml", Settings(), _options(tmp_path / "again")
    )
    assert first.speed == "max"
    # quick: seconds of this process's CPU time (wall time on a loaded machine is not the
    # run's cost; a fast-time run that slept in real time would still use little CPU, but
    # then it would not finish within the test's timeout)
    assert cpu_s <= 10.0, f"{cpu_s:.1f} s of CPU, {first.wall_clock_s} s wall"
    # the run happened: a loss of separation predicted, resolved, uploaded and verified
    assert any(t.kind == "LOSS_OF_SEPARATION" for t in first.threats)
    assert any(r.verified for r in first.recommendations)
    assert first.truth is not None and first.truth.pairs
    assert json.dumps(first.comparable(), sort_keys=True) == json.dumps(
        second.comparable(), sort_keys=True
    )
    on_disk = json.loads((tmp_path / "use_case_1.json").read_text())
    assert on_disk == first.to_json()


async def test_fast_time_refuses_an_ordinary_loop(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="fast time needs its own event loop"):
        await run_scenario(SCENARIOS / "use_case_1.toml", Settings(), _options(tmp_path))


def test_fast_time_with_external_autopilots_is_refused() -> None:
    with pytest.raises(ValueError, match="external autopilots run on their own clock"):
        RunOptions(speed=math.inf, external=True)


def test_cli_speed_max_runs_and_bad_speed_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = str(SCENARIOS / "use_case_2.toml")
    out = str(tmp_path)
    code = main(["run", path, "--speed", "max", "--auto-accept", "--headless", "--out", out])
    assert code == 0
    assert (tmp_path / "use_case_2.json").is_file()
    assert "scenario use_case_2:" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["run", path, "--speed", "fastest"])
    assert "expected a positive number or 'max', got 'fastest'" in capsys.readouterr().err
