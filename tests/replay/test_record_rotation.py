"""``--record``: rotation by size and by time ([record] max_file_mb / max_file_s), ADS-B feeds
recorded raw with their times and decoded back identically, the settings' errors naming the
key, an unusable folder refused at start, and a write failure mid-run survived."""

from __future__ import annotations

import logging
import os
import shutil
import time
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.adsb import ModeSDecoder, SbsDecoder
from adapters.adsb.capture import (
    CaptureDecoder,
    CaptureError,
    CaptureKind,
    LineSplitter,
    iter_capture,
    times_path,
)
from adapters.tlog import TlogReader
from gcs_utm.cli import main
from gcs_utm.cli.replay import replay_paths
from gcs_utm.config import ConfigError
from gcs_utm.services.record_config import RecordConfig
from gcs_utm.services.recorder import LinkRecorder, RecordError, check_folder
from gcs_utm.settings import settings_from_mapping
from tests.adsb.sbs_lines import sbs_position, sbs_velocity

T0 = 1_700_000_000.0
LINK = "udpin:127.0.0.1:14550"
FEED = "adsb-sbs:127.0.0.1:30003"


def _positions(n: int) -> list[bytes]:
    enc = mav.MAVLink(None, srcSystem=3, srcComponent=1)
    return [
        enc.global_position_int_encode(
            i * 100, 473977420 + i * 100, 85455940, 510000, 22000, 1, 2, 3, 0
        ).pack(enc)
        for i in range(n)
    ]


def _tlog_records(paths: list[Path]) -> list[tuple[float, bytes]]:
    return [(r.t_s, r.packet) for p in paths for r in TlogReader(p)]


def test_rotation_by_size_keeps_every_record_in_order(tmp_path: Path) -> None:
    frames = _positions(200)  # 40 bytes each: 48 bytes per tlog record, 9600 bytes in all
    cfg = RecordConfig(max_file_mb=0.001)  # 1000 bytes
    with LinkRecorder(tmp_path, config=cfg) as rec:
        for i, f in enumerate(frames):
            rec.tap(LINK, f, T0 + i * 0.01)
    paths = rec.all_files[LINK]
    assert len(paths) == 10  # 20 records of 48 bytes = 960 <= 1000 per file
    assert all(p.stat().st_size <= 1000 for p in paths)
    assert rec.counters.rotations == 9 and rec.counters.files == 10
    got = _tlog_records(paths)
    assert [p for _, p in got] == frames
    assert [t for t, _ in got] == pytest.approx([T0 + i * 0.01 for i in range(200)], abs=1e-6)


def test_rotation_by_time_starts_a_file_every_max_file_s(tmp_path: Path) -> None:
    frames = _positions(55)
    cfg = RecordConfig(max_file_s=2.0)
    with LinkRecorder(tmp_path, config=cfg) as rec:
        for i, f in enumerate(frames):
            rec.tap(LINK, f, T0 + i * 0.1)  # 5.4 s of records
    paths = rec.all_files[LINK]
    assert len(paths) == 3
    spans = [[r.t_s for r in TlogReader(p)] for p in paths]
    assert [len(s) for s in spans] == [20, 20, 15]
    assert all(s[-1] - s[0] < 2.0 for s in spans)
    assert [p for _, p in _tlog_records(paths)] == frames
    # the files are named by their first record's UTC time, in order
    assert paths[0].name == "udpin_127.0.0.1_14550-20231114T221320Z.tlog"
    assert sorted(paths) == paths


def _sbs_stream() -> bytes:
    lines = []
    for i in range(60):
        lines.append(sbs_velocity("a1b2c3", 120.0, 90.0, 0.0))
        lines.append(sbs_position("a1b2c3", 47.4, 8.5 + i * 0.001, 3000.0, callsign="TEST1"))
    lines.insert(17, "MSG,3,garbage")  # counted malformed, live and replayed
    return "".join(f"{line}\r\n" for line in lines).encode()


def test_feed_recorded_raw_rotated_and_decoded_back_as_live(tmp_path: Path) -> None:
    data = _sbs_stream()
    chunks = [data[i : i + 333] for i in range(0, len(data), 333)]  # lines cut across chunks
    live = SbsDecoder()
    cfg = RecordConfig(max_file_mb=0.002)
    splitter = LineSplitter()
    expected = []
    with LinkRecorder(tmp_path, config=cfg) as rec:
        for i, chunk in enumerate(chunks):
            t_s = T0 + i * 0.25
            rec.tap_feed(FEED, CaptureKind.SBS, chunk, t_s, i == 0)
            for line in splitter.feed(chunk, new_connection=i == 0):
                m = live.feed(line, t_s)
                if m is not None:
                    expected.append(m)
    pieces = rec.all_files[FEED]
    assert len(pieces) >= 3 and all(p.suffix == ".sbs" for p in pieces)
    assert all(times_path(p).is_file() for p in pieces)
    assert b"".join(p.read_bytes() for p in pieces) == data  # bytes as received
    assert rec.counters.feed_chunks == len(chunks)
    dec = CaptureDecoder(CaptureKind.SBS, SbsDecoder())
    got = [m for _, m in iter_capture(pieces, dec)]
    assert got == expected and len(got) == 60
    assert dec.decoder.counters.malformed == live.counters.malformed == 1


async def test_recorded_folder_replays_link_and_feed_merged_by_time(tmp_path: Path) -> None:
    frames = _positions(30)
    lines = [sbs_position("c0ffee", 47.40, 8.55 + i * 0.0005, 2000.0) for i in range(30)]
    with LinkRecorder(tmp_path, config=RecordConfig(max_file_s=5.0)) as rec:
        for i in range(30):
            rec.tap(LINK, frames[i], T0 + i * 0.5)
            rec.tap_feed(FEED, CaptureKind.SBS, f"{lines[i]}\n".encode(), T0 + i * 0.5, i == 0)
    assert len(rec.all_files[LINK]) == 3 and len(rec.all_files[FEED]) == 3
    report = await replay_paths([tmp_path])
    assert set(report["tracks"]) == {"sysid:3", "icao:c0ffee"}
    assert report["records"] == 30 and report["counters"]["adsb_capture_measurements"] == 30
    (feed,) = report["counters"]["adsb_feeds"].values()
    assert (feed["pieces"], feed["positions"], feed["rejects"]) == (3, 30, 0)
    assert report["duration"]["duration_s"] == pytest.approx(14.5)
    last = report["tracks"]["icao:c0ffee"]["last_position"]
    assert last["lon_deg"] == pytest.approx(8.55 + 29 * 0.0005, abs=2e-5)


def test_record_settings_errors_name_the_key() -> None:
    with pytest.raises(ConfigError, match=r"record\.max_file_mb"):
        settings_from_mapping({"record": {"max_file_mb": 0}}, source="site.toml")
    with pytest.raises(ConfigError, match=r"record\.max_file_s"):
        settings_from_mapping({"record": {"max_file_s": "1h"}}, source="site.toml")
    with pytest.raises(ConfigError, match=r"record\.max_size_mb: unknown key"):
        settings_from_mapping({"record": {"max_size_mb": 5}}, source="site.toml")
    s = settings_from_mapping({"record": {"max_file_mb": 5, "adsb": False}}, source="x")
    assert s.record.max_file_mb == 5.0 and not s.record.adsb


def test_unusable_folder_is_refused_at_start_with_one_line(tmp_path: Path, capsys) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(RecordError, match="cannot create the folder"):
        check_folder(blocker / "rec", RecordConfig())
    with pytest.raises(RecordError, match=r"MB free on its disk, \[record\] min_free_mb"):
        check_folder(tmp_path / "rec", RecordConfig(min_free_mb=1e6))
    code = main(["serve", "--headless", "--db", str(tmp_path / "db"), "--record", str(blocker)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f"gcs-utm: --record {blocker}: cannot create the folder: File exists"]
    assert not (tmp_path / "db").exists()  # refused before anything started


def test_a_write_failure_mid_run_stops_that_stream_logged_and_reported(
    tmp_path: Path, caplog
) -> None:
    folder = tmp_path / "rec"
    failures: list[str] = []
    frames = _positions(100)
    rec = LinkRecorder(folder, config=RecordConfig(max_file_mb=0.001), on_failure=failures.append)
    for i in range(10):
        rec.tap(LINK, frames[i], T0 + i * 0.01)
    # the disk goes away under the recorder: the next rotation cannot create its file
    deadline = time.monotonic() + 5.0
    while rec.counters.packets < 10 and time.monotonic() < deadline:
        time.sleep(0.01)
    shutil.rmtree(folder)
    with caplog.at_level(logging.ERROR, logger="gcs_utm.services.recorder"):
        for i in range(10, 100):
            rec.tap(LINK, frames[i], T0 + i * 0.01)  # never raises, never blocks
        rec.close()
    c = rec.counters
    assert c.write_errors == 1
    assert c.dropped_after_failure > 0
    assert c.packets + c.dropped_after_failure >= 90
    assert len(failures) == 1 and "recording of udpin:127.0.0.1:14550 stopped" in failures[0]
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "carries on" in errors[0].getMessage()


def test_capture_without_any_time_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "feed.sbs"
    path.write_text(sbs_position("a1b2c3", 47.4, 8.5, 3000.0) + "\n")
    with pytest.raises(CaptureError, match="no SBS-1 line carries a date/time"):
        list(iter_capture([path], CaptureDecoder(CaptureKind.SBS, SbsDecoder())))
    with pytest.raises(ValueError, match="matching decoder"):
        CaptureDecoder(CaptureKind.BEAST, SbsDecoder())
    assert CaptureDecoder(CaptureKind.AVR, ModeSDecoder()).kind is CaptureKind.AVR
