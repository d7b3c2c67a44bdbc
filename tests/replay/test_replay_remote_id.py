"""A replayed tlog ingests Remote ID as a live link does: the same OPEN_DRONE_ID_* records give
the same identities, the same REMOTE_ID_MISMATCH (a vehicle's Remote ID location 2 km from its
telemetry) and the same ``rid:`` track for an aircraft its receiver heard."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path
from typing import Any

import pytest
from replay_helpers import T0_S

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.remoteid.ingest import RidIngest, telemetry_positions
from adapters.tlog import TlogWriter
from gcs_utm.cli.replay import replay_file
from gcs_utm.clock import ManualClock
from gcs_utm.model import ThreatKind
from tests.mavlink.conftest import Sink

LAT, LON, ALT_AMSL_M = 47.3977419, 8.5455938, 520.5
SERIAL = b"1596A303716531B"
SERIAL_20 = list(SERIAL.ljust(20, b"\0"))
HEARD = b"\x60\x60\x1f\x01\x02\x03"  # the MAC of an aircraft the vehicle's receiver heard


def _packets() -> list[tuple[float, bytes]]:
    """PX4 quadrotor (pymavlink): HEARTBEAT and GLOBAL_POSITION_INT each second, from 2 s its
    Remote ID (Basic ID, Operator ID, a Location 2 km east) and an aircraft it heard."""
    enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    out: list[tuple[float, bytes]] = []

    def location(mac: bytes, lon_deg: float) -> Any:
        return enc.open_drone_id_location_encode(
            0, 0, list(mac.ljust(20, b"\0")), 2, 0, 500, 0, round(LAT * 1e7),
            round(lon_deg * 1e7), -1000, ALT_AMSL_M, 0, 30.0, 10, 4, 0, 3, 1.0, 1,
        )  # fmt: skip

    for k in range(8):
        t = T0_S + k
        hb = enc.heartbeat_encode(2, 12, 129, 4 << 16 | 4 << 24, 4)
        gp = enc.global_position_int_encode(
            k * 1000, round(LAT * 1e7), round(LON * 1e7), round(ALT_AMSL_M * 1e3), 30_000,
            0, 0, 0, 0,
        )  # fmt: skip
        msgs = [hb, gp]
        if k >= 2:
            msgs += [
                enc.open_drone_id_basic_id_encode(0, 0, [0] * 20, 1, 2, SERIAL_20),
                enc.open_drone_id_operator_id_encode(0, 0, [0] * 20, 0, b"FIN87astrdge12k8"),
                location(b"", LON + 0.026),  # its own, 2 km east of its telemetry
                location(HEARD, LON + 0.001),  # an aircraft heard 75 m east
            ]  # fmt: skip
        out += [(t + 0.01 * i, bytes(m.pack(enc))) for i, m in enumerate(msgs)]
    return out


def _live(packets: list[tuple[float, bytes]]) -> tuple[RidIngest, Sink]:
    """The same packets into a live hub with the service's Remote ID ingest."""

    async def run() -> tuple[RidIngest, Sink]:
        sink = Sink()
        clock = ManualClock(T0_S)
        cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), health_period_s=3600.0)
        hub = MavlinkHub(cfg, clock, sink)
        rid = RidIngest(consistency_m=150.0, position_of=telemetry_positions(hub))
        rid.register(hub.remote_id)
        await hub.start()
        try:
            link = next(iter(hub._links.values()))
            for t, data in packets:
                clock.set(t)
                hub._on_chunk(link, data, ("10.0.0.1", 14550))
            return rid, sink
        finally:
            await hub.close()

    return asyncio.run(run())


def test_replayed_remote_id_is_ingested_as_live(tmp_path: Path) -> None:
    packets = _packets()
    path = tmp_path / "rid.tlog"
    with TlogWriter(path) as w:
        for t, data in packets:
            w.write(t, data)
    report = asyncio.run(replay_file(path))
    live, sink = _live(packets)
    rid = report["remote_id"]
    assert rid["declared_sys_ids"] == [1]
    by_source = {i["source"]: i for i in rid["identities"]}
    assert set(by_source) == set(live.aircraft) == {"sysid:1", "rid:60601f010203"}
    own = by_source["sysid:1"]
    assert own["track_id"] == "sysid:1"
    assert (own["uas_id"], own["operator_id"]) == (SERIAL.decode(), "FIN87astrdge12k8")
    assert own["uas_id"] == live.aircraft["sysid:1"].uas_id
    assert own["lon_deg"] == pytest.approx(LON + 0.026)
    assert by_source["rid:60601f010203"]["track_id"] == "rid:60601f010203"
    for name in ("locations", "checked", "mismatches", "measurements"):
        assert rid["counters"][name] == getattr(live.counters, name), name
    assert rid["counters"]["mismatches"] == 6  # each of its 6 own Locations
    replayed = [h for h in report["hazards"] if h["kind"] == "REMOTE_ID_MISMATCH"]
    lived = [h for h in sink.hazards if h.kind is ThreatKind.REMOTE_ID_MISMATCH]
    assert [h["message"] for h in replayed] == [h.message for h in lived]
    assert "rid:60601f010203" in report["tracks"]  # the heard aircraft's track, as live
