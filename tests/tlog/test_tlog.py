"""tlog reading, corruption handling and recording on the real ArduSub recording (its replay:
tests/replay/test_replay.py)."""

from __future__ import annotations

import itertools
from datetime import UTC, datetime
from pathlib import Path

import pytest

from adapters.tlog import (
    TlogReader,
    TlogRecord,
    TlogWriter,
    TlogWriterClosedError,
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
