"""How the runtime stops its USM (gcs_utm.app.stopping.closing_steps, for serve and run
alike): a plain stop lets an upload in progress finish before the links close; a fenced
member (its region may be another instance's) cancels it and sends nothing more."""

from __future__ import annotations

import asyncio
import importlib
from types import SimpleNamespace
from typing import Any

import pytest

from gcs_utm.app.stopping import Stopping, closing_steps, run_steps
from gcs_utm.clock import ManualClock
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm

stopping_module = importlib.import_module("gcs_utm.app.stopping")


async def _stop_during_an_upload(*, fenced: bool) -> list[str]:
    usm = Usm(Airspace(), ManualClock(0.0))
    events: list[str] = []

    async def upload() -> None:  # the last exchange of a mission upload still to come
        await asyncio.sleep(0.05)
        events.append("upload acknowledged")

    async def close_links() -> None:
        events.append("links closed")

    usm._spawn(upload())
    rt: Any = SimpleNamespace(usm=usm, hub=SimpleNamespace(close=close_links))
    store: Any = SimpleNamespace(close=lambda: events.append("store closed"))
    await run_steps(
        Stopping(fenced=fenced), closing_steps(rt, store, None, Stopping(fenced=fenced))
    )
    return events


async def test_a_plain_stop_lets_the_upload_in_progress_finish_first() -> None:
    events = await _stop_during_an_upload(fenced=False)
    assert events == ["upload acknowledged", "links closed", "store closed"]


async def test_a_fenced_stop_cancels_it() -> None:
    events = await _stop_during_an_upload(fenced=True)
    assert events == ["links closed", "store closed"]


async def test_the_drain_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(stopping_module, "DRAIN_BUDGET_S", 0.05)
    usm = Usm(Airspace(), ManualClock(0.0))
    never = asyncio.Event()
    usm._spawn(never.wait())

    async def close_links() -> None:
        pass

    rt: Any = SimpleNamespace(usm=usm, hub=SimpleNamespace(close=close_links))
    store: Any = SimpleNamespace(close=lambda: None)
    stopping = Stopping(fenced=False)
    await asyncio.wait_for(run_steps(stopping, closing_steps(rt, store, None, stopping)), 5.0)
    assert stopping.overrun == []  # the drain gave up within its own budget
    assert not usm._tasks
