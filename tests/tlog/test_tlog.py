"""tlog reading, corruption handling, recording and replay on the real ArduSub recording."""

from __future__ import annotations

import itertools
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest

from adapters.tlog import (
    TlogCounters,
    TlogReader,
    TlogRecord,
    TlogWriter,
    TlogWriterClosedError,
    iter_messages,
    replay,
    scan_records,
)

TLOG = Path(__file__).resolve().parents[1] / "data" / "tlog" / "ardusub_log_tools_small.tlog"


@pytest.fixture(scope="module")
def tlog_path() -> Path:
    return TLOG


@pytest.fixture(scope="module")
def records(tlog_path: Path) -> list[TlogRecord]:
    return list(TlogReader(tlog_path))


@pytest.mark.data
def test_real_tlog_records_and_its_corrupt_chunks_are_counted(tlog_path, records):
    reader = TlogReader(tlog_path)
    assert list(reader) == records
    c = reader.counters
    # SOURCES.md: ~36k messages, 263 s, "a few corrupt chunks"
    assert c.records == len(records) == 35_912
    assert c.corrupt_chunks == 4
    assert c.skipped_bytes == 315
    assert c.truncated_tail == 0
    start = datetime.fromtimestamp(records[0].t_s, UTC)
    assert start.date().isoformat() == "2023-05-04"
    assert records[-1].t_s - records[0].t_s == pytest.approx(263.43, abs=0.01)
    assert all(b.t_s >= a.t_s - 1.0 for a, b in itertools.pairwise(records))
    # the pure scanner agrees with the chunked reader
    again, c2 = scan_records(tlog_path.read_bytes())
    assert again == records and c2 == c


@pytest.mark.data
def test_iter_messages_gives_the_vehicle_positions(tlog_path):
    counters = TlogCounters()
    positions = [
        (t, m)
        for t, m in iter_messages(tlog_path, counters=counters)
        if m.get_type() == "GLOBAL_POSITION_INT"
    ]
    assert counters.records == 35_912
    assert len(positions) == 792
    assert {m.get_srcSystem() for _, m in positions} == {1}
    for _, m in positions:
        # the BlueROV2 near the surface off Washington state
        assert abs(m.lat * 1e-7 - 48.3861) < 0.001
        assert abs(m.lon * 1e-7 - -124.6306) < 0.001
    assert positions[0][0] < positions[-1][0]


def _corrupt(data: bytes, offsets: list[int]) -> bytes:
    out = bytearray(data)
    for off in offsets:
        out[off] ^= 0x5A
    return bytes(out)


@pytest.mark.data
def test_flipped_bytes_are_skipped_and_counted_not_raised(tlog_path, records):
    data = tlog_path.read_bytes()[:200_000]
    clean, c0 = scan_records(data)
    # flip one byte inside 10 records spread over the file (past their timestamps)
    offsets = [20_000 * k + 13 for k in range(1, 10)]
    bad, c1 = scan_records(_corrupt(data, offsets))
    assert c1.corrupt_chunks >= c0.corrupt_chunks + 9
    lost = len(clean) - len(bad)
    assert 9 <= lost <= 9 * 3  # the hit record, at most a neighbour or two while resyncing
    assert set(bad) <= set(clean)  # nothing corrupt is emitted


@pytest.mark.data
def test_truncated_last_record_is_skipped(tmp_path, tlog_path):
    data = tlog_path.read_bytes()[:50_000]
    full, _ = scan_records(data)
    path = tmp_path / "cut.tlog"
    # cut in the middle of the last complete record's packet
    end_of_last = data.rfind(full[-1].packet) + len(full[-1].packet)
    path.write_bytes(data[: end_of_last - 5])
    reader = TlogReader(path)
    got = list(reader)
    assert got == full[:-1]
    assert reader.counters.truncated_tail == 1


@pytest.mark.data
def test_writer_round_trip_and_crash_safety(tmp_path, records):
    path = tmp_path / "rec.tlog"
    subset = records[:3000]
    with TlogWriter(path, batch_records=100) as w:
        for r in subset:
            w.write(r.t_s, r.packet)
        # batches of 100 are on disk before close; the last partial batch may not be
        assert path.stat().st_size >= sum(8 + len(r.packet) for r in subset[:2900])
    got = list(TlogReader(path))
    assert [(round(r.t_s, 6), r.packet) for r in got] == [
        (round(r.t_s, 6), r.packet) for r in subset
    ]
    assert w.closed
    with pytest.raises(TlogWriterClosedError):
        w.write(0.0, b"")
    # a crash mid-write leaves a partial record: the reader skips exactly that one
    with path.open("ab") as f:
        partial = int(subset[-1].t_s * 1e6 + 1).to_bytes(8, "big") + subset[-1].packet[:6]
        f.write(partial)
    reader = TlogReader(path)
    assert len(list(reader)) == len(subset)
    assert reader.counters.truncated_tail == 1


@pytest.mark.data
def test_writer_flushes_by_record_time(tmp_path, records):
    path = tmp_path / "t.tlog"
    w = TlogWriter(path, batch_records=10_000, flush_interval_s=1.0)
    t0 = records[0].t_s
    w.write(t0, records[0].packet)
    assert path.stat().st_size == 0
    w.write(t0 + 1.5, records[1].packet)  # older than the interval: flushed
    assert path.stat().st_size == 16 + len(records[0].packet) + len(records[1].packet)
    w.close()


@pytest.mark.data
async def test_replay_as_fast_as_possible_delivers_every_record_in_order(tlog_path, records):
    got: list[tuple[float, bytes]] = []
    stats = await replay(tlog_path, lambda t, p: got.append((t, p)), speed=None)
    assert got == [(r.t_s, r.packet) for r in records]
    assert stats.records == len(records)
    assert stats.duration_s == pytest.approx(263.43, abs=0.01)
    assert stats.counters.corrupt_chunks == 4


@pytest.mark.data
async def test_replay_paces_by_record_time(tmp_path, records):
    # 2 s of recording at speed 10 must take ~0.2 s
    t0 = records[0].t_s
    path = tmp_path / "two_seconds.tlog"
    with TlogWriter(path) as w:
        for r in records:
            if r.t_s - t0 > 2.0:
                break
            w.write(r.t_s, r.packet)
    arrivals: list[tuple[float, float]] = []
    start = time.monotonic()
    stats = await replay(
        path, lambda t, _p: arrivals.append((t, time.monotonic() - start)), speed=10.0
    )
    assert 0.17 <= stats.wall_s < 1.0
    for t, wall in arrivals:
        assert wall >= (t - t0) / 10.0 - 0.005  # never early
    with pytest.raises(ValueError):
        await replay(path, lambda t, p: None, speed=0.0)
