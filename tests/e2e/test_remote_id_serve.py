"""Remote ID under ``gcs-utm serve``, end to end: a vehicle flying its operation reports its
Remote ID over MAVLink with a location 2 km from where its telemetry says it is. gcs-utm
sends it the operator's part (it declared Remote ID), keeps its identity (event log and the
store's audit log) and raises REMOTE_ID_MISMATCH: stored, warned about, never a command to
the vehicle (the broadcast is wrong, not the flight)."""

from __future__ import annotations

import asyncio
import dataclasses
import time
from pathlib import Path
from typing import Any

from adapters.mavlink.config import MavlinkConfig
from adapters.remoteid.config import RemoteIdConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.core.emergency import EmergencyConfig
from gcs_utm.model import ThreatKind
from gcs_utm.settings import Settings
from gcs_utm.store import Store
from tests.e2e.test_sysid_conflict import OP, _at, _operation, _Sender, _until

SERIAL = b"1596A303716531B"


def _remote_id(sender: _Sender, port: int, t0_s: float) -> None:
    """The vehicle's own Remote ID: Basic ID, Operator ID and a Location 2 km east."""
    assert sender.transport is not None
    enc = sender.enc
    lat, lon = _at(time.time(), t0_s)
    msgs = (
        enc.open_drone_id_basic_id_encode(0, 0, [0] * 20, 1, 2, list(SERIAL.ljust(20, b"\0"))),
        enc.open_drone_id_operator_id_encode(0, 0, [0] * 20, 0, b"FIN87astrdge12k8"),
        enc.open_drone_id_location_encode(
            0, 0, [0] * 20, 2, 0, 500, 0, round(lat * 1e7), round((lon + 0.026) * 1e7),
            -1000, 82.0, 0, 50.0, 10, 4, 0, 3, 1.0, 1,
        ),
    )  # fmt: skip
    for msg in msgs:
        sender.transport.sendto(bytes(msg.pack(enc)), ("127.0.0.1", port))


async def test_spoofed_remote_id_is_a_stored_warning(tmp_path: Path) -> None:
    t0_s = time.time() - 5.0
    db = tmp_path / "utm.sqlite"
    store = Store(db)
    op = _operation(t0_s)
    store.save_operation(op)
    store.save_plan(op.plan)
    store.close()
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        emergency=EmergencyConfig(autonomous=True),
        remote_id=RemoteIdConfig(system_period_s=0.2),
    )
    stop = asyncio.Event()
    seen: dict[str, Any] = {}

    async def drive(rt: Runtime) -> None:
        loop = asyncio.get_running_loop()
        port = rt.hub.local_port(rt.hub.link_names()[0])
        _, vehicle = await loop.create_datagram_endpoint(
            lambda: _Sender(t0_s), local_addr=("127.0.0.1", 0)
        )
        seen["vehicle"] = vehicle

        async def fly() -> None:
            while not stop.is_set():
                vehicle.send_state(port)
                if rt.hub.counters.frames > 10:  # telemetry first, then Remote ID
                    _remote_id(vehicle, port, t0_s)
                await asyncio.sleep(0.1)

        def mismatch() -> bool:
            return any(t.kind is ThreatKind.REMOTE_ID_MISMATCH for t in rt.usm.threat_log)

        def got_system() -> bool:
            return any(m.get_type() == "OPEN_DRONE_ID_SYSTEM" for m in vehicle.received)

        task = asyncio.create_task(fly())
        try:
            await _until(mismatch, 15.0, "no REMOTE_ID_MISMATCH threat")
            await _until(got_system, 10.0, "no operator location sent to the vehicle")
            await asyncio.sleep(1.0)  # time for any command to reach the vehicle
            seen["threats"] = list(rt.usm.threat_log)
            seen["events"] = [e.text for e in rt.usm.events]
            seen["record"] = rt.remote_id_ingest.aircraft["sysid:1"]
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
    vehicle = seen["vehicle"]
    system = next(m for m in vehicle.received if m.get_type() == "OPEN_DRONE_ID_SYSTEM")
    first = op.plan.waypoints[0]  # no home filed: the take-off point is the first waypoint
    assert (system.operator_latitude, system.operator_longitude) == (
        round(first.lat_deg * 1e7),
        round(first.lon_deg * 1e7),
    )
    assert vehicle.suspend_commands() == []  # warned, not commanded
    threat = next(t for t in seen["threats"] if t.kind is ThreatKind.REMOTE_ID_MISMATCH)
    assert threat.uas_ids == (OP,) and "from the telemetry position" in threat.message
    assert seen["record"].uas_id == SERIAL.decode()
    assert any("uas id 1596A303716531B" in e for e in seen["events"])
    store = Store(db)
    try:
        assert [t.kind for t in store.load_threats() if t.id == threat.id] == [
            ThreatKind.REMOTE_ID_MISMATCH
        ]
        audit = store.load_audit()
        ident = [a for a in audit if a.actor == "remote-id" and a.subject == "sysid:1"]
        assert any(a.detail["uas_id"] == SERIAL.decode() for a in ident)
        assert any(a.action == "warn" and a.subject == threat.id for a in audit)
    finally:
        store.close()
