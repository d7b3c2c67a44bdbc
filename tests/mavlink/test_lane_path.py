"""The columnar position path (hub -> PositionLane -> USM -> tracking) against the Measurement
path it replaces: on the same datagrams, the same USM counters and per-source statistics (every
number), the same first altitudes, the same Measurements for a plain sink, and bit for bit
the same tracks. And the lane's handover: after each burst, within long bursts, per stream
chunk; the tracking buffer's full policy for lane entries."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav2

from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import ManualClock
from gcs_utm.core.tracking import TrackingConfig
from gcs_utm.core.tracking.tracker import Tracker
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    LANE_STRIDE,
    FlightPlan,
    LaneSource,
    Measurement,
    Operation,
    OperationId,
    PositionLane,
    SysId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.tracking import TrackingService
from gcs_utm.services.usm import Usm

T0 = 1_700_000_000.0
A, B, C = ("10.0.0.1", 14550), ("10.0.0.2", 14550), ("10.0.0.3", 14550)


def _gpi(enc: Any, boot_ms: int, lat_e7: int = 473977418, alt_mm: int = 500000) -> bytes:
    frame = bytes(
        enc.global_position_int_encode(
            boot_ms, lat_e7, 85455939, alt_mm, 10000, 120, -80, 30, 0
        ).pack(enc)
    )
    enc.seq = (enc.seq + 1) % 256
    return frame


def _stream() -> list[tuple[bytes, tuple[str, int]]]:
    """Three vehicles (two share system id 1), GPS accuracy arriving midway, a reboot, a
    duplicate, a corrupt datagram, a two-frame datagram, a position the tracker gates."""
    e1 = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    e2 = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    e3 = mav2.MAVLink(None, srcSystem=2, srcComponent=1)
    out: list[tuple[bytes, tuple[str, int]]] = []
    for enc, addr in ((e1, A), (e2, B), (e3, C)):
        out.append((bytes(enc.heartbeat_encode(2, 12, 129, 4 << 16, 4, 3).pack(enc)), addr))
        enc.seq = (enc.seq + 1) % 256
    for i in range(60):
        boot = 5000 + 100 * i if i < 45 else 100 * (i - 45)  # vehicle 1 reboots at i = 45
        frame = _gpi(e1, boot, 473977418 + 30 * i)
        out.append((frame, A))
        if i == 12:
            out.append((frame, A))  # a duplicated datagram
        if i == 20:
            gps = e1.gps_raw_int_encode(0, 3, 0, 0, 0, 80, 120, 0, 0, 12, 0, 1500, 2500, 0, 0)
            out.append((bytes(gps.pack(e1)), A))
            e1.seq = (e1.seq + 1) % 256
            bad = bytearray(frame)
            bad[-1] ^= 0xFF
            out.append((bytes(bad), A))
        out.append((_gpi(e2, 9000 + 100 * i, 473987418 + 20 * i), B))
        jump = 9_000_000 if i == 30 else 0  # ~1 km off: the gate rejects it
        out.append((_gpi(e3, 2000 + 100 * i, 473967418 + 25 * i + jump, 510000), C))
    out.append((_gpi(e3, 99999) + _gpi(e3, 100000), C))  # two frames, one datagram
    return out


def _operation() -> Operation:
    wps = (
        Waypoint4D(lat_deg=47.3967, lon_deg=8.5456, alt_amsl_m=510.0, t_s=T0),
        Waypoint4D(lat_deg=47.3977, lon_deg=8.5456, alt_amsl_m=510.0, t_s=T0 + 600),
    )
    op_id = OperationId("op2")
    return Operation(
        id=op_id,
        icao24=None,
        sys_id=SysId(2),
        priority=1,
        plan=FlightPlan(operation_id=op_id, version=1, waypoints=wps),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=5.0,
        operational_volume_m=15.0,
    )


async def _run(lane: bool, *, plain_sink: bool = False) -> dict[str, Any]:
    clock = ManualClock(T0)
    airspace = Airspace()
    usm = Usm(airspace, clock, position_lane=lane)
    tracker = Tracker(LocalFrame(47.3977418, 8.5455939, 500.0), TrackingConfig())
    tracking = TrackingService(tracker, clock)
    got: list[Measurement] = []
    if plain_sink:
        usm.attach_measurement_sink(got.append)
    else:
        usm.attach_measurement_sink(tracking.submit, tracking.submit_lane)
    # vehicles here share system ids across addresses on purpose: no sysid binding
    hub = MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",), sysid_binding=False), clock, usm)
    await hub.start()
    link = next(iter(hub._links.values()))
    for k, (data, addr) in enumerate(_stream()):
        clock.advance(0.01)
        hub._on_chunk(link, data, addr)
        if k % 7 == 6:
            hub.flush_positions()  # a burst ends (the UDP transport does it)
        if k % 40 == 39:
            hub.flush_positions()  # (the tracking cycle is another loop callback too)
            await tracking.step()
        if k == 100:
            # (another loop callback: never in the middle of a read burst)
            hub.flush_positions()
            airspace.add_operation(_operation())  # system id 2 is no longer unknown
            tracking.set_operations(airspace.operations.values())
    hub.flush_positions()
    await tracking.step()
    await hub.close()
    return {
        "counters": dict(usm.counters),
        "telemetry": usm.telemetry,
        "measurements": got,
        "tracker_counters": tracker.counters,
        "tracks": tracker.tracks(),
        "cov": {tid: tracker.covariance(tid) for tid in tracker.tracks()},
        "submitted": tracking.stats["submitted"],
    }


async def test_the_lane_gives_what_measurements_give() -> None:
    lane, plain = await _run(True), await _run(False)
    assert lane["counters"] == plain["counters"]
    assert lane["counters"]["measurements"] == 3 * 60 + 1 + 2
    assert 0 < lane["counters"]["unknown_vehicle_measurements"] < 3 * 60
    assert lane["telemetry"] == plain["telemetry"]  # every count, time and delay, exactly
    assert set(lane["telemetry"]) == {
        "telemetry:1@10.0.0.1:14550",
        "telemetry:1@10.0.0.2:14550",
        "telemetry:2@10.0.0.3:14550",
    }
    assert lane["tracker_counters"] == plain["tracker_counters"]
    assert lane["tracker_counters"]["gate"] >= 1 and lane["tracker_counters"]["duplicate"] >= 1
    assert lane["tracks"] == plain["tracks"] and set(lane["tracks"]) >= {"op2"}
    for tid, cov in plain["cov"].items():
        assert np.array_equal(lane["cov"][tid], cov)
    assert lane["submitted"] == plain["submitted"]


async def test_a_sink_without_a_lane_gets_the_same_measurements() -> None:
    lane, plain = await _run(True, plain_sink=True), await _run(False, plain_sink=True)
    assert len(lane["measurements"]) == 3 * 60 + 1 + 2
    assert lane["measurements"] == plain["measurements"]


async def test_the_lane_is_handed_over_within_a_long_burst_and_after_it() -> None:
    clock = ManualClock(T0)
    usm = Usm(Airspace(), clock)
    seen: list[int] = []
    usm.attach_measurement_sink(lambda m: None, lambda values, sources: seen.append(len(values)))
    # vehicles here share system ids across addresses on purpose: no sysid binding
    hub = MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",), sysid_binding=False), clock, usm)
    await hub.start()
    link = next(iter(hub._links.values()))
    enc = mav2.MAVLink(None, srcSystem=5, srcComponent=1)
    hub._on_chunk(link, bytes(enc.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(enc)), A)
    for i in range(40):  # one burst of 40 position reports
        hub._on_chunk(link, _gpi(enc, 1000 + 100 * i), A)
    assert seen == [16 * LANE_STRIDE, 16 * LANE_STRIDE]  # tracking need not wait for its end
    hub.flush_positions()  # the end of the burst
    assert seen[-1] == 8 * LANE_STRIDE
    assert usm.counters["measurements"] == 40
    await hub.close()


async def test_stream_links_hand_the_lane_over_after_every_chunk(tmp_path: Any) -> None:
    """A TCP link (SITL's tcp:...:5760) delivers chunks, not bursts: each chunk's positions
    reach the USM at once."""
    import asyncio

    got: list[bytes] = []
    enc = mav2.MAVLink(None, srcSystem=7, srcComponent=1)
    frames = bytes(enc.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(enc))
    enc.seq = 1
    frames += _gpi(enc, 1000) + _gpi(enc, 1100)

    done = asyncio.Event()

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        got.append(await reader.read(100))  # our heartbeat
        writer.write(frames)
        await writer.drain()
        while await reader.read(1000):  # until the hub closes the link
            pass
        writer.close()
        await writer.wait_closed()
        done.set()

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    clock = ManualClock(T0)
    usm = Usm(Airspace(), clock)
    counts: list[int] = []
    usm.attach_measurement_sink(lambda m: None, lambda values, sources: counts.append(len(values)))
    async with MavlinkHub(MavlinkConfig(links=(f"tcp:127.0.0.1:{port}",)), clock, usm):
        for _ in range(100):
            if usm.counters["measurements"] == 2:
                break
            await asyncio.sleep(0.01)
    await asyncio.wait_for(done.wait(), 5.0)
    server.close()
    await server.wait_closed()
    assert usm.counters["measurements"] == 2
    assert sum(counts) == 2 * LANE_STRIDE


def test_a_full_tracking_buffer_keeps_the_latest_lane_entry_per_vehicle() -> None:
    lane = PositionLane()
    for i in range(3):
        lane.register(LaneSource(SysId(i + 1), "l", ""))

    def entry(src: int, t: float) -> list[float]:
        return [src, t + 0.01, t, 8.5, 47.4, 500.0, 1.0, 0.0, 0.0, float("nan"), float("nan")]

    clock = ManualClock(T0)
    tr = Tracker(LocalFrame(47.4, 8.5, 500.0), TrackingConfig())
    svc = TrackingService(tr, clock, max_pending=2)
    svc.submit_lane(entry(0, T0) + entry(1, T0), lane.sources)
    svc.submit_lane(entry(0, T0 + 1.0) + entry(2, T0 + 1.0), lane.sources)  # full
    assert svc.stats == {**svc.stats, "submitted": 4, "replaced": 1, "dropped": 1}
    svc._ingest_pending()
    tracks = tr.tracks()
    assert set(tracks) == {"sysid:1", "sysid:2"}
    assert tracks["sysid:1"].t_s == T0 + 1.0  # the latest one replaced the first
    assert lane.measurement(entry(2, T0), 0).sys_id == 3
