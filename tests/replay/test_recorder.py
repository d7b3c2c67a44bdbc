"""LinkRecorder: splitting chunks into packets, drop-and-count, and a live round trip
(sitl vehicle -> MavlinkHub raw_tap -> .tlog -> replay)."""

from __future__ import annotations

import asyncio
import math
import os
import time
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.tlog import TlogReader
from gcs_utm.clock import ScaledClock
from gcs_utm.services.recorder import LinkRecorder, sanitise, split_packets
from tests.tlog_messages import tlog_messages


def _frames() -> list[bytes]:
    enc = mav.MAVLink(None, srcSystem=7, srcComponent=1)
    return [
        enc.heartbeat_encode(2, 12, 0, 0, 3).pack(enc),
        enc.global_position_int_encode(1000, 473977420, 85455940, 510000, 22000, 1, 2, 3, 0).pack(
            enc
        ),
        enc.statustext_encode(6, b"hello").pack(enc),
    ]


def test_split_packets_datagram_with_several_frames_garbage_and_a_cut_tail() -> None:
    a, b, c = _frames()
    bad = bytearray(b)
    bad[12] ^= 0xFF  # CRC no longer matches
    data = a + b"\x00\xfd\x07junk" + b + bytes(bad) + c[:7]
    packets, skipped, rest = split_packets(data)
    assert packets == [a, b]
    assert skipped == 7 + len(bad)  # the junk and the damaged frame, byte by byte
    assert data[rest:] == c[:7]  # the incomplete frame, for a stream link to carry over
    assert split_packets(a + c) == ([a, c], 0, len(a + c))


def test_sanitise() -> None:
    assert sanitise("udpin:127.0.0.1:14550") == "udpin_127.0.0.1_14550"
    assert sanitise("serial:/dev/ttyUSB0:57600") == "serial_dev_ttyUSB0_57600"
    assert sanitise("::") == "link"


def test_stream_chunks_split_mid_frame_are_reassembled(tmp_path: Path) -> None:
    frames = _frames()
    data = b"".join(frames)
    with LinkRecorder(tmp_path) as rec:
        for i in range(0, len(data), 10):  # TCP-like chunks cutting every frame
            rec.tap("tcp:127.0.0.1:5760", data[i : i + 10], 1_700_000_000.0 + i)
    [path] = rec.files.values()
    assert path.name.startswith("tcp_127.0.0.1_5760-")
    assert [r.packet for r in TlogReader(path)] == frames
    assert rec.counters.skipped_bytes == 0 and rec.counters.packets == 3


def test_udp_cut_frame_is_counted_not_carried(tmp_path: Path) -> None:
    a, b, _ = _frames()
    with LinkRecorder(tmp_path) as rec:
        rec.tap("udpin:127.0.0.1:0", a + b[:9], 1_700_000_000.0)
        rec.tap("udpin:127.0.0.1:0", b, 1_700_000_001.0)
    [path] = rec.files.values()
    assert [r.packet for r in TlogReader(path)] == [a, b]
    assert rec.counters.truncated == 1


def test_full_queue_drops_and_counts_nothing_silently(tmp_path: Path) -> None:
    a = _frames()[0]
    rec = LinkRecorder(tmp_path, max_queue=2)
    for i in range(2000):
        rec.tap("udpin:x", a, 1_700_000_000.0 + i * 1e-3)
    rec.close()
    c = rec.counters
    assert c.chunks + c.dropped_chunks == 2000
    [path] = rec.files.values()
    assert sum(1 for _ in TlogReader(path)) == c.packets == c.chunks
    rec.tap("udpin:x", a, 0.0)  # after close: ignored, not an error


class _Sink:
    def __init__(self) -> None:
        self.positions: list[Any] = []

    def on_measurement(self, m: Any) -> None:
        self.positions.append(m)

    def on_status(self, s: Any) -> None: ...
    def on_hazard(self, h: Any) -> None: ...
    def on_vehicle(self, v: Any) -> None: ...
    def on_link_health(self, h: Any) -> None: ...


async def test_record_a_sitl_vehicle_through_the_hub_and_replay_it(tmp_path: Path) -> None:
    from sitl import Fleet, SimTime, VehicleSpec

    speed = 5.0
    start = math.floor(time.time())
    clock = ScaledClock(speed, start_utc_s=start)
    sink = _Sink()
    rec = LinkRecorder(tmp_path)
    hub = MavlinkHub(MavlinkConfig(links=()), clock, sink, raw_tap=rec.tap)
    async with hub:
        link = await hub.add_link("udpin:127.0.0.1:0")
        port = hub.local_port(link)
        spec = VehicleSpec(instance=0, gcs_port=port, bind_port=0, home_alt_amsl_m=488.0)
        sim = SimTime(speed, start_utc_s=start, start_mono_s=clock.start_mono_s)
        async with Fleet([spec], sim):
            await asyncio.sleep(2.0)
    rec.close()
    assert rec.counters.dropped_chunks == 0 and rec.counters.write_errors == 0
    [path] = rec.files.values()
    got = [(t, m) for t, m in tlog_messages(path)]
    live = [m for m in sink.positions if m.sys_id == 1]
    replayed = [m for _, m in got if m.get_type() == "GLOBAL_POSITION_INT"]
    assert len(live) >= 10  # ~2 s x speed 5 x 5 Hz, capped by the real-rate limit
    assert len(replayed) == len(live)  # every position frame on the wire was recorded
    for m_live, m_rec in zip(live, replayed, strict=True):
        assert m_rec.lat / 1e7 == m_live.lat_deg and m_rec.lon / 1e7 == m_live.lon_deg
    assert abs(replayed[0].lat / 1e7 - 47.397742) < 1e-4  # PX4 SITL home
    # sent frames are recorded too (our heartbeats, sysid 255)
    assert any(m._header.srcSystem == 255 for _, m in got)
    # record times are the hub clock's (simulated) times, in order
    times = [t for t, _ in got]
    assert times == sorted(times) and start <= times[0] <= times[-1] <= start + 2.5 * speed
    # and the replay pipeline finds the vehicle and its track in the recording
    from gcs_utm.cli.replay import replay_file

    r = await replay_file(path)
    [v] = r["vehicles"]
    assert (v["sys_id"], v["autopilot"], v["positions"]) == (1, "px4", len(live))
    assert r["tracks"]["sysid:1"]["updates"] == len(live)
    assert r["counters"]["corrupt_records"] == 0
