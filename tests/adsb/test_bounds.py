"""Per-aircraft decoder state stays bounded under spoofed ICAO addresses (issue 21 item 3):
capped at ``max_aircraft`` while the flood lasts, empty after ``aircraft_idle_s`` of silence."""

from __future__ import annotations

import pytest

from adapters.adsb import ModeSDecoder, SbsDecoder
from adapters.adsb.config import AdsbConfig
from gcs_utm.clock import ManualClock
from gcs_utm.config import ConfigError, build
from gcs_utm.services.surveillance import SurveillanceService
from tests.adsb.sbs_lines import sbs_position

# An odd and an even airborne position (TC 11) of 406B90 from the pyModeS sample recording,
# and its identification (TC 4): templates whose ICAO address is replaced.
ODD = "8D406B9058B975870B738754F480"
EVEN = "8D406B9058B98218DD7D364566EF"
IDENT = "8D406B902015A678D4D220AA4BDA"
SPOOFED = 12_000
CAP = 1_000
IDLE_S = 30.0


def _crc24(data: bytes) -> int:
    """Mode-S parity (generator 0xFFF409) of the first 88 bits of an extended squitter."""
    crc = 0
    for byte in data:
        crc ^= byte << 16
        for _ in range(8):
            crc = ((crc << 1) ^ 0xFFF409) & 0xFFFFFF if crc & 0x800000 else (crc << 1) & 0xFFFFFF
    return crc


def _spoof(frame: str, icao: int) -> str:
    """``frame`` sent by ``icao``: a CRC-valid DF17 frame the decoder takes as real."""
    body = frame[:2] + f"{icao:06X}" + frame[8:22]
    return body + f"{_crc24(bytes.fromhex(body)):06X}"


def test_spoof_helper_makes_the_original_frame_back():
    assert _spoof(ODD, 0x406B90) == ODD


def _flood(dec: ModeSDecoder) -> float:
    """12,000 spoofed addresses, each an identification and a CPR pair; returns the end."""
    t_s = 0.0
    for i in range(SPOOFED):
        icao = 0x100000 + i
        t_s = i * 0.001
        for frame in (IDENT, ODD, EVEN):
            dec.feed_hex(_spoof(frame, icao), t_s)
        assert dec.state_size() <= CAP
    return t_s


def test_pair_decoder_state_is_capped_then_empty_after_idle():
    dec = ModeSDecoder(max_aircraft=CAP, aircraft_idle_s=IDLE_S)
    end_s = _flood(dec)
    assert dec.counters.identifications == SPOOFED  # every frame was taken as valid
    assert dec.counters.aircraft_evicted >= SPOOFED - CAP
    dec.evict_idle(end_s + IDLE_S + 1.0)  # no frame after the flood: the service's sweep
    assert dec.state_size() == 0
    assert dec.aircraft() == {}


def test_reference_decoder_state_is_capped_then_empty_after_idle():
    dec = ModeSDecoder(51.99, 4.375, max_aircraft=CAP, aircraft_idle_s=IDLE_S)
    end_s = _flood(dec)
    assert dec.counters.positions == 2 * SPOOFED
    assert dec.counters.aircraft_evicted >= SPOOFED - CAP
    # a frame after the idle time sweeps by itself (no service needed)
    dec.feed_hex(IDENT, end_s + IDLE_S + 1.0)
    assert dec.aircraft() == {"406b90": "EZY85MH"}


def test_sbs_decoder_state_is_capped_then_empty_after_idle():
    dec = SbsDecoder(max_aircraft=CAP, aircraft_idle_s=IDLE_S)
    t_s = 0.0
    for i in range(SPOOFED):
        t_s = i * 0.001
        dec.feed(sbs_position(f"{0x100000 + i:06x}", 52.0, 4.4, 3000, callsign="SPOOF"), t_s)
        assert dec.state_size() <= CAP
    assert dec.counters.positions == SPOOFED
    assert dec.counters.aircraft_evicted >= SPOOFED - CAP
    dec.evict_idle(t_s + IDLE_S + 1.0)
    assert dec.state_size() == 0
    assert dec.aircraft() == {}


def test_service_sweeps_every_feed_with_its_clock():
    clock = ManualClock(0.0)
    config = AdsbConfig(
        enabled=True, sbs_port=30003, avr_port=30002, max_aircraft=CAP, aircraft_idle_s=IDLE_S
    )
    svc = SurveillanceService(config, clock, lambda m: None)
    sbs, avr = svc.feeds[0].sbs, svc.feeds[1].modes
    assert sbs is not None and avr is not None
    for i in range(2 * CAP):
        sbs.feed(sbs_position(f"{0x200000 + i:06x}", 52.0, 4.4, 3000), 0.0)
        avr.feed_hex(_spoof(IDENT, 0x200000 + i), 0.0)
    assert sbs.state_size() <= CAP and avr.state_size() <= CAP
    clock.set(IDLE_S + 1.0)
    assert svc.evict_idle() > 0
    assert sbs.state_size() == 0 and avr.state_size() == 0
    assert svc.stats()["sbs:127.0.0.1:30003"]["aircraft_evicted"] >= CAP


def test_bounds_out_of_range_are_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"adsb\.max_aircraft"):
        build(AdsbConfig, {"max_aircraft": 0}, source="site.toml", section="adsb")
    with pytest.raises(ConfigError, match=r"adsb\.aircraft_idle_s"):
        build(AdsbConfig, {"aircraft_idle_s": 0.0}, source="site.toml", section="adsb")
