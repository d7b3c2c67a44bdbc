"""MonitoringService: periodic on the injected clock, threats delivered, cancel-safe."""

from __future__ import annotations

import asyncio
import contextlib

from gcs_utm.clock import ManualClock
from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import AirspaceSnapshot, Threat
from gcs_utm.services.monitoring import MonitoringService


async def test_runs_each_period_and_cancels_cleanly() -> None:
    clock = ManualClock(1000.0)
    seen: list[float] = []
    delivered: list[list[Threat]] = []

    def provider(t_s: float) -> AirspaceSnapshot:
        seen.append(t_s)
        return AirspaceSnapshot(t_s=t_s, operations={}, tracks={}, geofences=())

    async def sink(ts: list[Threat]) -> None:
        delivered.append(ts)

    svc = MonitoringService(
        Monitor(LocalFrame(37.4, -6.0), MonitoringConfig()), provider, clock, sink, 1.0
    )
    task = asyncio.create_task(svc.run())
    for _ in range(20):
        await asyncio.sleep(0)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    assert len(seen) >= 3
    assert seen[1] - seen[0] == 1.0  # one period on the injected clock
    assert delivered == []  # empty airspace: nothing to report
    assert svc.run_once(5000.0) == []
