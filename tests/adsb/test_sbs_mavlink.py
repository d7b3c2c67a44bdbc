"""SBS-1 BaseStation lines and MAVLink ADSB_VEHICLE fields -> measurements."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest

from adapters.adsb import (
    AdsbFlags,
    SbsDecoder,
    SbsFormatError,
    adsb_vehicle_to_measurement,
    decode_sbs_line,
)
from gcs_utm.model import MeasurementSource

# dump1090-fa style lines (22 fields), aircraft 3C6444 near Frankfurt
HEAD = "MSG,{},1,1,3C6444,1,2024/05/04,{},2024/05/04,{},"
ID = HEAD.format(1, "12:00:00.000", "12:00:00.010") + "DLH4AB  ,,,,,,,,0,0,0,0"
POS = HEAD.format(3, "12:00:01.500", "12:00:01.510") + ",12000,,,50.03190,8.57060,,,0,0,0,0"
VEL = HEAD.format(4, "12:00:01.000", "12:00:01.010") + ",,300,90.0,,,-640,,0,0,0,0"
T_POS = datetime(2024, 5, 4, 12, 0, 1, 500_000, tzinfo=UTC).timestamp()


def test_position_line_is_decoded_with_generated_time_and_metres():
    m = decode_sbs_line(POS, receipt_t_s=T_POS + 0.2)
    assert m is not None
    assert m.source is MeasurementSource.ADSB
    assert m.icao24 == "3c6444"
    assert (m.lat_deg, m.lon_deg) == (50.0319, 8.5706)
    assert m.alt_amsl_m == pytest.approx(12000 * 0.3048)
    assert m.capture_t_s == pytest.approx(T_POS)
    assert m.receipt_t_s == pytest.approx(T_POS + 0.2)
    assert decode_sbs_line(POS, 5.0, use_generated_time=False).capture_t_s == 5.0  # type: ignore[union-attr]


def test_non_position_lines_give_none():
    assert decode_sbs_line(ID, 0.0) is None
    assert decode_sbs_line(VEL, 0.0) is None


def test_malformed_line_raises_with_field():
    with pytest.raises(SbsFormatError) as info:
        decode_sbs_line(POS.replace("50.03190", "fifty"), 0.0)
    assert info.value.field == "latitude"
    with pytest.raises(SbsFormatError) as info:
        decode_sbs_line(POS.replace("3C6444", "XYZ"), 0.0)
    assert info.value.field == "hex ident"
    with pytest.raises(SbsFormatError):
        decode_sbs_line("MSG,3,1,1,3C6444", 0.0)


def test_decoder_merges_callsign_and_velocity_and_counts_bad_lines():
    dec = SbsDecoder()
    lines = [ID, VEL, "garbage", "", POS.replace(",12000,", ",abc,"), POS, "STA,,5,179,400AE7"]
    out = [dec.feed(line, T_POS) for line in lines]
    ms = [m for m in out if m is not None]
    assert len(ms) == 1
    m = ms[0]
    assert m.callsign == "DLH4AB"
    assert m.vel_ned_mps is not None
    n, e, d = m.vel_ned_mps
    assert n == pytest.approx(0.0, abs=1e-9)
    assert e == pytest.approx(300 * 1852 / 3600)
    assert d == pytest.approx(640 * 0.3048 / 60)  # descending
    assert dec.counters.malformed == 3
    assert dec.counters.positions == 1
    assert dec.aircraft() == {"3c6444": "DLH4AB"}


def test_old_velocity_is_not_attached():
    dec = SbsDecoder(velocity_max_age_s=0.2)
    dec.feed(VEL, 0.0)
    m = dec.feed(POS, 0.0)
    assert m is not None and m.vel_ned_mps is None  # VEL generated 0.5 s before POS


# ---- MAVLink ADSB_VEHICLE --------------------------------------------------------------------

VALID = AdsbFlags.VALID_COORDS | AdsbFlags.VALID_ALTITUDE | AdsbFlags.VALID_HEADING
VALID |= AdsbFlags.VALID_VELOCITY | AdsbFlags.VALID_CALLSIGN


def _fields(**over: object) -> dict[str, object]:
    f: dict[str, object] = {
        "icao_address": 0x3C6444,
        "lat_e7": 403_850_000,
        "lon_e7": -37_100_000,
        "altitude_type": 1,
        "altitude_mm": 152_400,
        "heading_cdeg": 9000,
        "hor_velocity_cms": 2500,
        "ver_velocity_cms": 150,
        "callsign": "EC-ABC\x00\x00",
        "tslc_s": 2,
        "flags": int(VALID),
        "receipt_t_s": 1000.0,
        "link": "udp:14550",
    }
    f.update(over)
    return f


def test_adsb_vehicle_fields_convert_units():
    m = adsb_vehicle_to_measurement(**_fields())  # type: ignore[arg-type]
    assert m is not None
    assert m.icao24 == "3c6444"
    assert (m.lat_deg, m.lon_deg) == pytest.approx((40.385, -3.71))
    assert m.alt_amsl_m == pytest.approx(152.4)
    assert m.capture_t_s == 998.0 and m.receipt_t_s == 1000.0
    assert m.vel_ned_mps is not None
    n, e, d = m.vel_ned_mps
    assert (n, e, d) == pytest.approx((0.0, 25.0, -1.5), abs=1e-9)
    assert math.hypot(n, e) == pytest.approx(25.0)
    assert m.callsign == "EC-ABC"
    assert m.link == "udp:14550"


def test_adsb_vehicle_without_valid_position_or_velocity():
    assert adsb_vehicle_to_measurement(**_fields(flags=int(AdsbFlags.VALID_ALTITUDE))) is None  # type: ignore[arg-type]
    assert adsb_vehicle_to_measurement(**_fields(icao_address=0x1000000)) is None  # type: ignore[arg-type]
    no_vel = int(AdsbFlags.VALID_COORDS | AdsbFlags.VALID_ALTITUDE)
    m = adsb_vehicle_to_measurement(**_fields(flags=no_vel, callsign=b"X"))  # type: ignore[arg-type]
    assert m is not None and m.vel_ned_mps is None and m.callsign == ""
