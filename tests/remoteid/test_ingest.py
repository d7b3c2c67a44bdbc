"""What vehicles report of Remote ID (adapters/remoteid/ingest.py) through a real hub: identity
on the vehicle's record, a spoofed location as a REMOTE_ID_MISMATCH hazard, an aircraft heard by
a vehicle's receiver as the non-cooperative track ``rid:<id>``, message packs decoded."""

from __future__ import annotations

import asyncio
import os
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.remoteid.f3411 import IdType, UaType
from adapters.remoteid.ingest import RidAircraft, RidIngest, identity_audit, telemetry_positions
from gcs_utm.clock import RealClock
from gcs_utm.model import SysId, ThreatKind, TrackId
from tests.mavlink.conftest import FakeVehicle, Sink
from tests.remoteid.test_f3411 import _hex
from tests.tracking.tracking_helpers import new_tracker

LAT, LON = 47.3977, 8.5456  # FakeVehicle.position()'s default
SERIAL = b"1596A303716531B"
MAC = [0x60, 0x60, 0x1F, 0x01, 0x02, 0x03] + [0] * 14


class _Env:
    def __init__(self, hub: MavlinkHub, sink: Sink, port: int) -> None:
        self.hub, self.sink, self.port = hub, sink, port
        self.identity: list[tuple[RidAircraft, str]] = []
        self.rid = RidIngest(
            consistency_m=150.0,
            position_of=telemetry_positions(hub),
            on_identity=lambda rec, text: self.identity.append((rec, text)),
        )
        self.rid.register(hub.remote_id)

    async def vehicle(self, sys_id: int) -> FakeVehicle:
        v = await FakeVehicle(self.port, sys_id).start()
        v.heartbeat()
        await _until(lambda: any(i.key.sys_id == sys_id for i in self.hub.vehicles()))
        return v

    def hazards(self) -> list[Any]:
        return [h for h in self.sink.hazards if h.kind is ThreatKind.REMOTE_ID_MISMATCH]


async def _until(cond: Any, timeout_s: float = 3.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not cond():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.01)


@pytest.fixture
async def env() -> Any:
    hub = MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",)), RealClock(), sink := Sink())
    await hub.start()
    link = next(iter(hub.link_names()))
    yield _Env(hub, sink, hub.local_port(link))
    await hub.close()


def _location(v: FakeVehicle, lat: float, lon: float, *, mac: list[int] | None = None) -> None:
    v.send(
        v.mav.open_drone_id_location_encode(
            0, 0, mac or [0] * 20, 2, 9000, 500, 0, round(lat * 1e7), round(lon * 1e7),
            -1000, 530.0, 0, 40.0, 10, 4, 0, 3, 12.3, 1,
        ),
        lossy=False,
    )  # fmt: skip


def _basic_id(v: FakeVehicle, serial: bytes, *, mac: list[int] | None = None) -> None:
    uas_id = list(serial.ljust(20, b"\0"))
    v.send(v.mav.open_drone_id_basic_id_encode(0, 0, mac or [0] * 20, 1, 2, uas_id), lossy=False)


async def test_spoofed_location_raises_a_threat_a_true_one_does_not(env: Any) -> None:
    v = await env.vehicle(1)
    v.position()
    await _until(lambda: env.hub.state(SysId(1)).last_position is not None)
    _location(v, LAT + 0.0003, LON)  # 33 m off: within 150 m + the 10 m accuracy class
    await _until(lambda: env.rid.counters.checked == 1)
    assert env.hazards() == []
    _location(v, LAT + 0.02, LON)  # 2.2 km off
    await _until(lambda: env.rid.counters.checked == 2)
    [h] = env.hazards()
    assert h.sys_id == 1 and "2224 m from the telemetry position" in h.message
    assert h.position.lat_deg == pytest.approx(LAT + 0.02)
    # the vehicle's own Remote ID location is checked, never a second position of it
    assert not [m for m in env.sink.measurements if "remote-id" in m.link]
    v.close()


async def test_identity_and_a_change_in_flight(env: Any) -> None:
    v = await env.vehicle(2)
    _basic_id(v, SERIAL)
    v.send(v.mav.open_drone_id_operator_id_encode(0, 0, [0] * 20, 0, b"FIN87astrdge12k8"))
    await _until(lambda: env.rid.aircraft.get("sysid:2", None) is not None)
    await _until(lambda: env.rid.aircraft["sysid:2"].operator_id != "")
    rec = env.rid.aircraft["sysid:2"]
    assert (rec.uas_id, rec.id_type, rec.ua_type) == (
        SERIAL.decode(),
        IdType.SERIAL_NUMBER,
        UaType(2),
    )
    assert rec.operator_id == "FIN87astrdge12k8" and rec.sys_id == 2
    rec2, text = next((r, t) for r, t in env.identity if "1596A303716531B" in t)
    assert text.startswith("sysid:2: Remote ID uas id 1596A303716531B")
    audit = identity_audit(env.rid.aircraft["sysid:2"])  # what the store's audit log gets
    assert (audit.actor, audit.action, audit.subject) == ("remote-id", "identity", "sysid:2")
    assert audit.detail["uas_id"] == "1596A303716531B"
    assert audit.detail["operator_id"] == "FIN87astrdge12k8" and rec2.key == "sysid:2"
    assert env.hazards() == []
    _location(v, LAT, LON)  # airborne (status 2); no telemetry position: its position
    await _until(lambda: env.rid.counters.measurements == 1)
    [m] = [m for m in env.sink.measurements if "remote-id" in m.link]
    assert m.sys_id == 2 and m.alt_amsl_m == 530.0 and m.eph_m == 5.0
    _basic_id(v, b"18656A24303")  # another serial while airborne
    await _until(lambda: bool(env.hazards()))
    assert "identity changed in flight: 1596A303716531B -> 18656A24303" in env.hazards()[0].message
    v.close()


async def test_aircraft_heard_by_a_receiver_becomes_a_rid_track(env: Any) -> None:
    v = await env.vehicle(3)
    _basic_id(v, SERIAL, mac=MAC)
    _location(v, LAT + 0.01, LON, mac=MAC)
    await _until(lambda: env.rid.counters.measurements == 1)
    key = "rid:60601f010203"
    assert env.rid.aircraft[key].uas_id == SERIAL.decode() and env.rid.aircraft[key].sys_id is None
    assert 3 not in env.hub.remote_id.declared  # heard, not its own
    [m] = [m for m in env.sink.measurements if m.vehicle == key]
    assert m.sys_id is None and m.lat_deg == pytest.approx(LAT + 0.01)
    tracker = new_tracker()
    tracker.ingest([m])
    track = tracker.tracks()[TrackId(key)]
    assert not track.cooperative and track.lat_deg == pytest.approx(LAT + 0.01)
    v.close()


async def test_message_pack_decoded_into_the_record(env: Any) -> None:
    v = await env.vehicle(4)
    names = ("basic_id", "cli_location", "self_id", "system", "operator_id")
    messages = [_hex(f"librid_{name}.hex") for name in names]  # librid's published messages
    pack = b"".join(messages)
    v.send(
        v.mav.open_drone_id_message_pack_encode(0, 0, MAC, 25, 5, list(pack.ljust(225, b"\0"))),
        lossy=False,
    )
    await _until(lambda: env.rid.counters.packs == 1)
    rec = env.rid.aircraft["rid:60601f010203"]
    assert rec.uas_id == "1ABCD2345EF678XYZ"
    assert rec.self_id == "Drone delivery test"
    assert rec.operator_id == "FIN87astrdge12k8"
    assert rec.position is not None and rec.position.lat_deg == pytest.approx(62.683472)
    assert rec.operator_position is not None
    assert rec.operator_position.lon_deg == pytest.approx(24.5397187)
    # a broken pack is counted, not raised
    v.send(v.mav.open_drone_id_message_pack_encode(0, 0, MAC, 24, 1, [0] * 225), lossy=False)
    await _until(lambda: env.rid.counters.bad == 1)
    v.close()
