"""``serve`` on a shared PostgreSQL store (``[store] url``): what another instance filed is
the airspace this one starts with, and this instance's life is a row of the same database."""

from __future__ import annotations

import asyncio
import dataclasses
from pathlib import Path

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.scenario import load_scenario
from gcs_utm.settings import Settings
from gcs_utm.store import StoreConfig, open_store
from tests.store.test_store import UC1, _fence


async def test_serve_resumes_from_a_postgresql_store(pg_url: str, tmp_path: Path) -> None:
    sc = load_scenario(UC1)
    with open_store(pg_url) as other:
        lives_before = len(other.lives())
        for op in sc.operations:
            other.save_operation(op)
        other.save_geofence(_fence("GF-shared"))
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        store=StoreConfig(url=pg_url),
    )
    stop = asyncio.Event()
    seen: dict[str, object] = {}

    async def on_runtime(rt: Runtime) -> None:
        seen["ops"] = sorted(rt.airspace.operations)
        seen["fences"] = [g.id for g in rt.airspace.geofences()]
        seen["epoch"] = rt.store.epoch
        stop.set()

    code = await asyncio.wait_for(
        serve(
            settings,
            db_path=tmp_path / "unused.sqlite",
            operator=OperatorMode.NONE,
            headless=True,
            stop=stop,
            on_runtime=on_runtime,
        ),
        timeout=30.0,
    )
    assert code == 0
    assert seen["ops"] == sorted(op.id for op in sc.operations)
    assert seen["fences"] == ["GF-shared"]
    assert not (tmp_path / "unused.sqlite").exists()
    with open_store(pg_url) as s:
        assert len(s.lives()) == lives_before + 1
        assert s.lives()[-1][0] == seen["epoch"]
