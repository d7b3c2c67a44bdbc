"""A vehicle's Remote ID identity and location on its track, in the store and over MQTT, under
``gcs-utm serve`` with a real mosquitto: the vehicle flies its operation and reports its
Remote ID (Basic ID, Operator ID, Location) over MAVLink; a remote pilot station subscribed to
the traffic topic sees the identity on the operation's track, the service's track snapshot
carries it, and the store holds it (the remote_ids table and the track's document)."""

from __future__ import annotations

import asyncio
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "mqtt"))

from mqtt_helpers import make_broker, peer

from adapters.mavlink.config import MavlinkConfig
from adapters.mqtt.codec import Topics
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.settings import Settings
from gcs_utm.store import Store
from tests.e2e.test_sysid_conflict import OP, _at, _operation, _Sender, _until

SERIAL = b"1596A303716531B"
OPERATOR = b"FIN87astrdge12k8"


def _remote_id(sender: _Sender, port: int, t0_s: float) -> tuple[float, float]:
    """The vehicle's own Remote ID, its Location where its telemetry puts it (20 m higher)."""
    assert sender.transport is not None
    enc = sender.enc
    lat, lon = _at(time.time(), t0_s)
    msgs = (
        enc.open_drone_id_basic_id_encode(0, 0, [0] * 20, 1, 2, list(SERIAL.ljust(20, b"\0"))),
        enc.open_drone_id_operator_id_encode(0, 0, [0] * 20, 0, OPERATOR),
        enc.open_drone_id_location_encode(
            0, 0, [0] * 20, 2, 0, 500, 0, round(lat * 1e7), round(lon * 1e7),
            -1000, 102.0, 0, 50.0, 10, 4, 0, 3, 1.0, 1,
        ),
    )  # fmt: skip
    for msg in msgs:
        sender.transport.sendto(bytes(msg.pack(enc)), ("127.0.0.1", port))
    return lat, lon


async def test_remote_id_on_the_track_in_the_store_and_over_mqtt(tmp_path: Path) -> None:
    broker = make_broker(tmp_path)
    t0_s = time.time() - 5.0
    db = tmp_path / "utm.sqlite"
    store = Store(db)
    op = _operation(t0_s)
    store.save_operation(op)
    store.close()
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        mqtt=broker.config(traffic_rate_hz=5.0),
    )
    stop = asyncio.Event()
    seen: dict[str, Any] = {}

    async def drive(rt: Runtime) -> None:
        loop = asyncio.get_running_loop()
        port = rt.hub.local_port(rt.hub.link_names()[0])
        _, vehicle = await loop.create_datagram_endpoint(
            lambda: _Sender(t0_s), local_addr=("127.0.0.1", 0)
        )

        async def fly() -> None:
            while not stop.is_set():
                vehicle.send_state(port)
                if rt.hub.counters.frames > 10:  # telemetry first, then Remote ID
                    seen["sent"] = _remote_id(vehicle, port, t0_s)
                await asyncio.sleep(0.1)

        task = asyncio.create_task(fly())
        try:
            async with (
                peer(broker, "alice", (Topics("gcs_utm").traffic,)) as alice,
                asyncio.timeout(15.0),  # then: no Remote ID in the traffic feed
            ):
                while True:  # the first traffic message with the vehicle's Remote ID
                    _, msg, _ = await alice.next(Topics("gcs_utm").traffic)
                    mine = [t for t in msg["tracks"] if t["track_id"] == OP]
                    if mine and mine[0]["remote_id"] and mine[0]["remote_id"]["operator_id"]:
                        seen["mqtt"] = mine[0]
                        break
            track = rt.tracks()[OP]
            seen["track"] = track
            # the store's rows come with the tracking flushes: wait for one after the above
            await _until(
                lambda: rt.tracking.tracker.tracks()[OP].t_s > track.t_s + 1.5, 10.0, "no flush"
            )
        finally:
            stop.set()
            await task
            vehicle.transport.close()

    drivers: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        drivers.append(asyncio.create_task(drive(rt)))

    try:
        code = await serve(
            settings,
            db_path=db,
            operator=OperatorMode.NONE,
            headless=False,
            stop=stop,
            on_runtime=on_runtime,
        )
    finally:
        broker.stop()
    assert code == 0
    await drivers[0]
    lat, _lon = seen["sent"]
    rid = seen["mqtt"]["remote_id"]
    assert rid["source"] == "sysid:1"
    assert (rid["uas_id"], rid["id_type"], rid["ua_type"]) == (
        SERIAL.decode(),
        "SERIAL_NUMBER",
        "HELICOPTER_OR_MULTIROTOR",
    )
    assert rid["operator_id"] == OPERATOR.decode()
    assert rid["lat_deg"] == pytest.approx(lat, abs=1e-3) and rid["alt_m"] == 102.0
    assert rid["location_t_s"] is not None
    track = seen["track"]
    assert track.remote_id is not None and track.remote_id.uas_id == SERIAL.decode()
    assert track.remote_id.operator_id == OPERATOR.decode()
    store = Store(db)
    try:
        [(track_id, stored)] = store.load_remote_ids()
        assert track_id == OP and stored.source == "sysid:1"
        assert (stored.uas_id, stored.operator_id) == (SERIAL.decode(), OPERATOR.decode())
        assert stored.alt_m == 102.0 and stored.location_t_s is not None
        latest = {t.id: t for t in store.latest_tracks()}
        assert latest[OP].remote_id is not None
        assert latest[OP].remote_id.uas_id == SERIAL.decode()
    finally:
        store.close()
