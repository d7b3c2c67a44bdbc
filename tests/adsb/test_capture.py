"""ADS-B captures read back (adapters/adsb/capture.py): how captures without a sidecar are
timed, and what a damaged sidecar or a data file longer than its sidecar gives."""

from __future__ import annotations

from pathlib import Path

import pytest

from adapters.adsb import ModeSDecoder, SbsDecoder
from adapters.adsb.capture import (
    CaptureDecoder,
    CaptureError,
    CaptureKind,
    CaptureWriter,
    iter_capture,
)
from tests.adsb.encode import CSV_T0_S, beast, csv_frames
from tests.adsb.sbs_lines import sbs_position

REFERENCE = (51.99, 4.375)


def _modes(kind: CaptureKind) -> CaptureDecoder:
    return CaptureDecoder(kind, ModeSDecoder(*REFERENCE))


def test_sbs_lines_before_the_first_date_take_it(tmp_path: Path) -> None:
    when = "2024/01/02,03:04:05.500"
    timed = f"MSG,3,1,1,A1B2C3,1,{when},{when},,3000,,,47.4,8.5,,,0,0,0,0"
    path = tmp_path / "feed.sbs"
    untimed = sbs_position("c0ffee", 47.5, 8.6, 2000.0)  # no generated date/time
    path.write_text(f"{untimed}\n{timed}\n{untimed}")  # no newline at the end
    dec = CaptureDecoder(CaptureKind.SBS, SbsDecoder())
    got = list(iter_capture([path], dec))
    t = 1704164645.5  # 2024-01-02 03:04:05.5 UTC
    assert [(ts, m.icao24) for ts, m in got] == [(t, "c0ffee"), (t, "a1b2c3"), (t, "c0ffee")]
    assert dec.counters.untimed_lines == 2


def test_beast_times_follow_the_mlat_counter_and_survive_a_reset(tmp_path: Path) -> None:
    rows = [(t, h) for t, h in csv_frames() if len(h) == 28][:200]
    data = bytearray()
    for i, (t, h) in enumerate(rows):
        ticks = round((t - CSV_T0_S) * 12e6)
        if i >= 100:  # the receiver restarts: its counter starts again near 0
            ticks = round((t - rows[100][0]) * 12e6) + 1
        data += beast(h, ticks)
    path = tmp_path / "feed.bin"
    path.write_bytes(bytes(data))
    dec = _modes(CaptureKind.BEAST)
    got = list(iter_capture([path], dec, start_t_s=CSV_T0_S))
    assert dec.counters.mlat_resets == 1
    assert dec.decoder.beast_counters.frames == 200  # counted where a live feed counts them
    truth = {round(t, 3) for t, _ in rows}
    before = [ts for ts, _ in got if ts < rows[100][0] - 1e-3]
    assert before and all(round(ts, 3) in truth for ts in before)  # exact until the reset
    times = [ts for ts, _ in got]
    assert times == sorted(times)  # the reset re-anchors, time does not jump back


def test_avr_at_lines_are_timed_by_mlat_star_lines_by_the_previous(tmp_path: Path) -> None:
    rows = csv_frames()[:40]
    lines = []
    for i, (t, h) in enumerate(rows):
        ticks = round((t - CSV_T0_S) * 12e6)
        lines.append(f"*{h};" if i % 2 else f"@{ticks:012X}{h};")
    path = tmp_path / "feed.avr"
    path.write_text("\n".join(lines) + "\n")
    dec = _modes(CaptureKind.AVR)
    got = list(iter_capture([path], dec, start_t_s=CSV_T0_S))
    assert got and dec.counters.untimed_lines == 20
    for ts, m in got:
        assert ts <= m.capture_t_s + 1.0


def test_data_beyond_the_sidecar_is_decoded_at_the_last_time(tmp_path: Path) -> None:
    path = tmp_path / "feed.sbs"
    w = CaptureWriter(path)
    w.write(100.0, (sbs_position("a1b2c3", 47.4, 8.5, 3000.0) + "\n").encode(), new_connection=True)
    w.close()
    with path.open("ab") as f:  # a crash between the data and the sidecar write
        f.write((sbs_position("a1b2c3", 47.41, 8.5, 3000.0) + "\n").encode())
    dec = CaptureDecoder(CaptureKind.SBS, SbsDecoder())
    got = list(iter_capture([path], dec))
    assert [ts for ts, _ in got] == [100.0, 100.0]
    assert dec.counters.untimed_tail_bytes > 0


def test_malformed_sidecar_line_is_named(tmp_path: Path) -> None:
    path = tmp_path / "feed.sbs"
    path.write_text(sbs_position("a1b2c3", 47.4, 8.5, 3000.0) + "\n")
    path.with_name("feed.sbs.times").write_text("12 xx 0\n")
    with pytest.raises(CaptureError, match=r"feed\.sbs\.times: line 1: expected"):
        list(iter_capture([path], CaptureDecoder(CaptureKind.SBS, SbsDecoder())))
