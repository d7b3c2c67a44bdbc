"""The runtime owns its start and teardown (gcs_utm.app.wiring.Runtime, an async context
manager): a failure while ``serve`` or ``run`` is still starting tears down what was started
(the links, the USM's work, the store writer), as a normal stop does."""

from __future__ import annotations

import asyncio
import dataclasses
from pathlib import Path

import pytest

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, RunOptions, Runtime, run_scenario_blocking, serve
from gcs_utm.settings import Settings
from gcs_utm.store import StoreError

SCENARIO = Path(__file__).resolve().parents[2] / "config" / "scenarios" / "use_case_1.toml"


class StartFailedError(RuntimeError):
    pass


def _assert_torn_down(rt: Runtime) -> None:
    assert rt.hub.links() == []  # every link closed
    assert not rt.usm._tasks
    with pytest.raises(StoreError, match="closed"):
        rt.store.writer.submit(lambda s: None)
    assert not rt.store.writer._thread.is_alive()


async def test_a_failure_while_serve_starts_tears_down_what_was_started(tmp_path: Path) -> None:
    settings = dataclasses.replace(Settings(), mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)))
    seen: list[Runtime] = []

    async def fail_on_start(rt: Runtime) -> None:
        seen.append(rt)
        assert len(rt.hub.links()) == 1  # the link is open by now
        raise StartFailedError("a part could not start")

    with pytest.raises(StartFailedError):
        await serve(
            settings,
            db_path=tmp_path / "utm.sqlite",
            operator=OperatorMode.NONE,
            headless=False,
            stop=asyncio.Event(),
            on_runtime=fail_on_start,
        )
    _assert_torn_down(seen[0])


def test_a_failure_while_a_run_starts_tears_down_what_was_started(tmp_path: Path) -> None:
    options = RunOptions(
        speed=float("inf"),
        headless=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        duration_s=5.0,
        figures=False,
    )
    seen: list[Runtime] = []

    async def fail_on_start(rt: Runtime) -> None:
        seen.append(rt)
        raise StartFailedError("a part could not start")

    with pytest.raises(StartFailedError):
        run_scenario_blocking(SCENARIO, Settings(), options, on_runtime=fail_on_start)
    _assert_torn_down(seen[0])
