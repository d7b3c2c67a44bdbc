"""Raw Mode-S decoding: a real Beast recording (Toulouse) and a synthetic DF17 stream written
by our own encoder (``tests/adsb/encode.py``, so every position is checked against where the
aircraft was): counts, accuracy, corruption handling."""

from __future__ import annotations

import itertools
import json
import math
import os
import random
from pathlib import Path

import pytest

from adapters.adsb import BeastFramer, ModeSDecoder, ModeSFrameError, parse_avr_line
from gcs_utm.geo import haversine_m
from gcs_utm.model import Measurement, MeasurementSource
from tests.adsb.encode import CSV_FLIGHT, CSV_T0_S

pytestmark = pytest.mark.data

# Receivers: the synthetic CSV aircraft flies over the Netherlands; the Beast sample was
# recorded around Toulouse.
CSV_REFERENCE = (51.99, 4.375)
TOULOUSE = (43.6, 1.44)

GOLDEN = Path(__file__).with_name("golden") / "beast_positions.json"
# Regenerate with: GCS_UTM_REGEN_GOLDEN=1 pytest tests/adsb/test_modes.py -k golden
# (then review the diff: the file is what a user's replay of this recording must produce).


def _decode_csv(rows: list[tuple[float, str]], dec: ModeSDecoder) -> list[Measurement]:
    return [m for t, hex_ in rows if (m := dec.feed_hex(hex_, t)) is not None]


def test_csv_with_reference_decodes_every_position_of_the_one_aircraft(csv_rows):
    dec = ModeSDecoder(*CSV_REFERENCE)
    ms = _decode_csv(csv_rows, dec)
    c = dec.counters
    assert c.frames == 1320
    assert c.corrupt == 0 and c.not_adsb == 60  # the all-call replies
    assert dec.aircraft() == {"4ca7e9": "GCS1234"}
    # Every airborne-position frame becomes a measurement with a receiver reference.
    assert c.positions == len(ms) == 600
    assert c.velocities == 600
    for m in ms:
        assert m.source is MeasurementSource.ADSB
        assert m.icao24 == "4ca7e9"
        # where the encoder put it, within the 17-bit CPR resolution (~5 m)
        lat, lon = CSV_FLIGHT.at(m.capture_t_s - CSV_T0_S)
        assert haversine_m(lat, lon, m.lat_deg, m.lon_deg) < 6.0
        assert haversine_m(*CSV_REFERENCE, m.lat_deg, m.lon_deg) < 333_360.0
        # FL360 pressure altitude in metres
        assert m.alt_amsl_m == pytest.approx(36_000 * 0.3048)
        assert m.capture_t_s == m.receipt_t_s
    with_vel = [m for m in ms if m.vel_ned_mps is not None]
    assert len(with_vel) == 599  # the first position comes before the first velocity
    n, e, d = with_vel[0].vel_ned_mps  # type: ignore[misc]
    # 490 kt (in whole knots per axis) heading 290 degrees: west-north-west
    assert math.hypot(n, e) == pytest.approx(490.0 * 1852.0 / 3600.0, rel=3e-3)
    assert math.degrees(math.atan2(e, n)) % 360.0 == pytest.approx(290.0, abs=0.2)
    assert d == 0.0
    assert ms[-1].callsign == "GCS1234"


def test_consecutive_positions_are_consistent_with_the_reported_speed(csv_rows):
    ms = _decode_csv(csv_rows, ModeSDecoder(*CSV_REFERENCE))
    for a, b in itertools.pairwise(ms):
        dt = b.capture_t_s - a.capture_t_s
        dist = haversine_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg)
        # 252 m/s ground speed, +/- the CPR resolution of both positions
        assert dist == pytest.approx(252.1 * dt, abs=10.0), (a, b)


def test_pair_decoding_without_reference_agrees_with_reference_decoding(csv_rows):
    with_ref = ModeSDecoder(*CSV_REFERENCE)
    dec = ModeSDecoder()
    compared = 0
    for t, hex_ in csv_rows:
        r = with_ref.feed_hex(hex_, t)
        m = dec.feed_hex(hex_, t)
        if m is not None:
            assert r is not None
            # the same frame resolved two ways: CPR resolution is ~5 m at this latitude
            assert haversine_m(r.lat_deg, r.lon_deg, m.lat_deg, m.lon_deg) < 10.0
            compared += 1
    assert compared > 590
    assert dec.counters.pending_cpr + compared == 600


def test_reference_too_far_drops_and_counts_out_of_range(csv_rows):
    dec = ModeSDecoder(*CSV_REFERENCE, max_range_m=10_000.0)
    assert _decode_csv(csv_rows[:200], dec) == []
    assert dec.counters.out_of_range > 0


def test_beast_file_one_adsb_aircraft_near_toulouse(beast_bytes):
    dec = ModeSDecoder(*TOULOUSE)
    ms = dec.feed_beast(beast_bytes, 1_581_500_000.0)
    assert dec.beast_counters.frames == 239
    assert dec.beast_counters.truncated == 0
    assert dec.counters.frames == 239
    assert dec.counters.corrupt == 0
    assert list(dec.aircraft()) == ["48520a"]
    assert dec.aircraft()["48520a"] == "TRA89M"
    assert len(ms) == dec.counters.positions == 4
    for m in ms:
        assert haversine_m(*TOULOUSE, m.lat_deg, m.lon_deg) < 50_000.0
        assert 11_000.0 < m.alt_amsl_m < 12_000.0
        assert m.eph_m is not None and m.eph_m < 100.0  # NACp from operational status


def test_beast_any_chunking_gives_the_same_frames(beast_bytes):
    whole = [f.hex for f in BeastFramer().feed(beast_bytes)]
    rng = random.Random(7)
    for _ in range(20):
        framer = BeastFramer()
        got: list[str] = []
        i = 0
        while i < len(beast_bytes):
            step = rng.randint(1, 40)
            got += [f.hex for f in framer.feed(beast_bytes[i : i + step])]
            i += step
        assert got == whole


def test_beast_golden(beast_bytes):
    dec = ModeSDecoder(*TOULOUSE)
    out = [
        {
            "icao24": m.icao24,
            "lat_deg": round(m.lat_deg, 6),
            "lon_deg": round(m.lon_deg, 6),
            "alt_amsl_m": round(m.alt_amsl_m, 2),
            "vel_ned_mps": None if m.vel_ned_mps is None else [round(v, 3) for v in m.vel_ned_mps],
            "eph_m": None if m.eph_m is None else round(m.eph_m, 3),
            "callsign": m.callsign,
        }
        for m in dec.feed_beast(beast_bytes, 0.0)
    ]
    if os.environ.get("GCS_UTM_REGEN_GOLDEN"):
        GOLDEN.parent.mkdir(exist_ok=True)
        GOLDEN.write_text(json.dumps(out, indent=1) + "\n")
    expected = json.loads(GOLDEN.read_text())
    assert expected, f"{GOLDEN} is empty: regenerate it (see the comment at the top)"
    assert out == expected


# ---- corruption -----------------------------------------------------------------------------


def _flip_bit(hex_: str, bit: int) -> str:
    value = int(hex_, 16) ^ (1 << bit)
    return f"{value:0{len(hex_)}X}"


def test_flipped_bits_fail_crc_and_are_counted_not_emitted(csv_rows):
    rng = random.Random(1)
    dec = ModeSDecoder(*CSV_REFERENCE)
    corrupted = 0
    emitted = []
    extended = [(t, h) for t, h in csv_rows if len(h) == 28]  # DF17, not the DF11 replies
    for t, original in extended[:500]:
        hex_ = original
        if rng.random() < 0.3:
            # flip a bit outside the DF field so it stays DF17 and must fail the CRC
            hex_ = _flip_bit(original, rng.randrange(0, 107))
            corrupted += 1
        m = dec.feed_hex(hex_, t)
        if m is not None:
            emitted.append(m)
    assert dec.counters.crc_failed == corrupted
    assert all(m.icao24 == "4ca7e9" for m in emitted)
    assert dec.counters.frames == 500


def test_truncated_and_garbage_avr_lines_are_counted(csv_rows):
    dec = ModeSDecoder(*CSV_REFERENCE)
    lines = [f"*{h};" for _, h in csv_rows[:50]]
    lines[3] = lines[3][:20]  # truncated frame
    lines[7] = f"*ZZZZ{csv_rows[7][1][4:]};"
    lines[9] = "hello"
    lines[11] = f"@000000000000{csv_rows[11][1]};"  # MLAT prefix: valid
    out = [dec.feed_avr(line, csv_rows[0][0]) for line in lines]
    assert dec.counters.malformed == 3
    assert dec.counters.frames == 50
    assert sum(m is not None for m in out) > 15


def test_parse_avr_line_errors_carry_the_frame():
    with pytest.raises(ModeSFrameError) as info:
        parse_avr_line("*8D40;")
    assert info.value.frame == "*8D40;"
    assert "hex" in info.value.reason


def test_beast_truncated_frames_are_skipped_and_counted(beast_bytes):
    good = BeastFramer().feed(beast_bytes)
    # truncate every 20th frame: drop the 3 bytes before the next frame's marker, so the next
    # marker cuts the body short (what a receiver restart or a lost TCP segment produces)
    markers = [
        i
        for i in range(1, len(beast_bytes) - 1)
        if beast_bytes[i] == 0x1A
        and beast_bytes[i + 1] in (0x32, 0x33)
        and beast_bytes[i - 1] != 0x1A
    ]
    cut = set(markers[5::20])
    data = bytearray()
    for i, b in enumerate(beast_bytes):
        if any(0 < m - i <= 3 for m in cut):
            continue
        data.append(b)
    framer = BeastFramer()
    frames = framer.feed(bytes(data) + b"\x00\x01garbage")
    assert framer.counters.truncated + len(frames) >= len(good) - len(cut)
    assert framer.counters.truncated >= 1
    assert len(frames) >= len(good) - 2 * len(cut)
    assert framer.counters.skipped_bytes >= 9
    # and the surviving frames decode without exceptions
    dec = ModeSDecoder(*TOULOUSE)
    for f in frames:
        dec.feed_hex(f.hex, 0.0)
    assert dec.counters.frames == len(frames)
