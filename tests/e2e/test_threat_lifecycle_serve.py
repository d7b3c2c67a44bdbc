"""Against ``serve`` over loopback UDP: a vehicle that goes silent raises
COMMUNICATION_FAILURE and EM's temporary geofence; when its positions flow again (a PX4
reboot, an ArduPilot restart, a link restored) the threat closes, in the store and on the
status line, with the reason audited, and the geofence goes with it (issue 31)."""

from __future__ import annotations

import asyncio
import dataclasses
import time
from pathlib import Path
from typing import Any

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.model import ThreatKind, ThreatStatus
from gcs_utm.services.usm import UsmConfig
from gcs_utm.settings import Settings
from gcs_utm.store import Store
from tests.e2e.test_sysid_conflict import _operation, _Sender, _until


async def test_link_loss_closes_when_positions_flow_again_and_its_fence_goes(
    tmp_path: Path,
) -> None:
    t0_s = time.time() - 5.0
    db = tmp_path / "utm.sqlite"
    store = Store(db)
    op = _operation(t0_s)
    store.save_operation(op)
    store.save_plan(op.plan)
    store.close()
    base = Settings()
    settings = dataclasses.replace(
        base,
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        tracking=dataclasses.replace(base.tracking, stale_after_s=1.0),
        usm=UsmConfig(threat_clear_s=1.0),
    )
    stop = asyncio.Event()
    seen: dict[str, Any] = {}

    async def drive(rt: Runtime) -> None:
        loop = asyncio.get_running_loop()
        port = rt.hub.local_port(rt.hub.link_names()[0])
        _, vehicle = await loop.create_datagram_endpoint(
            lambda: _Sender(t0_s), local_addr=("127.0.0.1", 0)
        )
        silent = asyncio.Event()

        async def fly() -> None:
            while not stop.is_set():
                if not silent.is_set():
                    vehicle.send_state(port)
                await asyncio.sleep(0.1)

        task = asyncio.create_task(fly())

        def lost() -> list[Any]:
            return [
                t for t in rt.usm.threats.values() if t.kind is ThreatKind.COMMUNICATION_FAILURE
            ]

        try:
            await _until(lambda: rt.hub.counters.frames > 10, 10.0, "vehicle not heard")
            silent.set()
            await _until(lambda: bool(lost()), 10.0, "no COMMUNICATION_FAILURE")
            seen["threat"] = lost()[0]
            fence_id = f"em-{seen['threat'].id}-{op.id}"
            await _until(
                lambda: any(g.id == fence_id for g in rt.airspace.geofences()),
                10.0,
                "no link-loss geofence",
            )
            seen["fence"] = fence_id
            silent.clear()  # positions flow again
            await _until(lambda: not lost(), 15.0, "COMMUNICATION_FAILURE stayed open")
            await _until(
                lambda: all(g.id != fence_id for g in rt.airspace.geofences()),
                10.0,
                "the geofence stayed",
            )
            seen["events"] = [e.text for e in rt.usm.events]
        finally:
            stop.set()
            await task
            vehicle.transport.close()

    drivers: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        drivers.append(asyncio.create_task(drive(rt)))

    code = await serve(
        settings,
        db_path=db,
        operator=OperatorMode.NONE,
        headless=False,
        stop=stop,
        on_runtime=on_runtime,
    )
    assert code == 0
    await drivers[0]
    threat = seen["threat"]
    assert any("geofence" in e and "removed" in e for e in seen["events"])
    store = Store(db)
    try:
        (row,) = [t for t in store.load_threats() if t.id == threat.id]
        assert row.status is ThreatStatus.CLOSED and "flow again" in row.message
        audit = store.load_audit()
        closed = [a for a in audit if a.action == "threat_closed" and a.subject == threat.id]
        assert any("flow again" in str(a.detail.get("reason")) for a in closed)
        assert any(a.action == "geofences_removed" and a.subject == threat.id for a in audit)
        assert seen["fence"] not in {g.id for g in store.load_geofences(active_only=True)}
    finally:
        store.close()
