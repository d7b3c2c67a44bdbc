"""The bounded stop of ``serve`` (gcs_utm.app.stopping): a service task that ignores its
cancellation and a close step that never completes are named in the log and left behind
within the budget, instead of keeping a fenced instance alive."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from gcs_utm.app import stopping as stopping_module
from gcs_utm.app.stopping import Stopping, run_steps


async def test_a_stuck_task_and_a_stuck_step_are_named_and_left_behind(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(stopping_module, "FENCED_BUDGET_S", 0.5)
    release = asyncio.Event()

    async def deaf() -> None:  # swallows its cancellation, as a hung shutdown step does
        while not release.is_set():
            try:
                await asyncio.sleep(10)
            except asyncio.CancelledError:
                continue

    async def fine() -> None:
        await asyncio.sleep(10)

    tasks = [asyncio.create_task(deaf(), name="deaf"), asyncio.create_task(fine(), name="fine")]
    await asyncio.sleep(0)  # both running
    closed: list[str] = []
    never = asyncio.Event()

    async def hangs() -> None:
        await never.wait()

    started = time.monotonic()
    stop = Stopping(fenced=True)
    with caplog.at_level(logging.ERROR):
        assert await stop.cancel(tasks) == ["deaf"]
        await run_steps(stop, [("links", hangs), ("store.close", lambda: closed.append("store"))])
    assert time.monotonic() - started < 1.5
    assert stop.overrun == ["task deaf", "links"]
    assert closed == ["store"]  # the steps after the stuck one still ran
    assert "task deaf did not end" in caplog.text and "links did not finish" in caplog.text
    release.set()
    tasks[0].cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
