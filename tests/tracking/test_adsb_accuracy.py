"""ADS-B accuracy -> measurement noise: NACp (95 % bound, DO-260B) and, without a NACp, the
position's containment radius by type code; and that this noise is what the filter uses.

Frames are real ones from the dump1090 Beast sample (aircraft 48520a near Toulouse) with
single fields rewritten and the Mode-S parity recomputed (own CRC below, not pyModeS's)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from adapters.adsb import ModeSDecoder, nacp_to_eph_m
from adapters.adsb.common import typecode_to_eph_m
from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import Icao24, Measurement, TrackId

TOULOUSE = (43.6, 1.44)
TC31_V2_NACP9 = "8D48520AF82300060049B898BA5F"
TC29_SUB1_NACP9 = "8D48520AEA4A5867C53C08219A7D"
TC11_POSITION = "8D48520A58C38118524B549E1B08"
# DO-260B Table 2-69 (the table the brief quotes), 95 % horizontal bound in metres.
EPU95_M = {
    11: 3.0,
    10: 10.0,
    9: 30.0,
    8: 92.6,
    7: 185.2,
    6: 555.6,
    5: 926.0,
    4: 1852.0,
    3: 3704.0,
    2: 7408.0,
    1: 18520.0,
}
K95 = math.sqrt(-2.0 * math.log(0.05))  # 95 % radius of a circular normal, in sigmas


def _parity(data_hex: str) -> str:
    """Mode-S CRC-24 (generator 0x1FFF409) of the 88 data bits of an extended squitter."""
    rem = int(data_hex, 16) << 24
    for bit in range(87, -1, -1):
        if rem & (1 << (bit + 24)):
            rem ^= 0x1FFF409 << bit
    return f"{rem & 0xFFFFFF:06X}"


def _me_rewrite(frame: str, shift: int, width: int, value: int) -> str:
    """Set ``width`` bits of the 56-bit ME field at ``shift`` (from its LSB), fix parity."""
    me = int(frame[8:22], 16)
    mask = ((1 << width) - 1) << shift
    me = (me & ~mask) | (value << shift)
    data = frame[:8] + f"{me:014X}"
    return data + _parity(data)


def test_own_crc_reproduces_the_recorded_parity() -> None:
    for frame in (TC31_V2_NACP9, TC29_SUB1_NACP9, TC11_POSITION):
        assert frame[22:] == _parity(frame[:22])


def tc31(nac_p: int, version: int = 2) -> str:
    # pyModeS bds65: nac_p = (ME >> 8) & 0xF, version = (ME >> 13) & 0x7.
    return _me_rewrite(_me_rewrite(TC31_V2_NACP9, 8, 4, nac_p), 13, 3, version)


def tc29(nac_p: int, subtype: int = 1) -> str:
    # pyModeS bds62: nac_p = (ME >> 13) & 0xF, subtype = (ME >> 49) & 0x3.
    return _me_rewrite(_me_rewrite(TC29_SUB1_NACP9, 13, 4, nac_p), 49, 2, subtype)


def position(typecode: int = 11) -> str:
    return _me_rewrite(TC11_POSITION, 51, 5, typecode)


@pytest.mark.parametrize(("nac_p", "epu_m"), sorted(EPU95_M.items()))
def test_nacp_sigma_puts_95_percent_inside_the_bound(nac_p: int, epu_m: float) -> None:
    sigma = nacp_to_eph_m(nac_p)
    assert sigma is not None
    # Sampled, not the formula again: per-axis normal noise of that sigma.
    rng = np.random.default_rng(nac_p)
    r = np.hypot(*rng.normal(0.0, sigma, size=(2, 400_000)))
    assert np.mean(r <= epu_m) == pytest.approx(0.95, abs=0.002)


@pytest.mark.parametrize("nac_p", [None, 0, 12, 15])
def test_unknown_nacp_gives_no_accuracy(nac_p: int | None) -> None:
    assert nacp_to_eph_m(nac_p) is None


def test_typecode_fallback_is_never_tighter_than_the_standards_bounds() -> None:
    # (type code, v1/v2 NIC containment radius Rc, v0 NUCp 95 % radius R_cu), both the
    # largest the type code allows; the fallback 95 % radius must cover both.
    bounds = {
        9: (7.5, 3.0),
        10: (25.0, 10.0),
        11: (185.2, 92.6),
        12: (370.4, 185.2),
        13: (1111.2, 463.0),
        14: (1852.0, 926.0),
        15: (3704.0, 1852.0),
        16: (14816.0, 9260.0),
        17: (37040.0, 18520.0),
        20: (7.5, 3.0),
        21: (25.0, 10.0),
    }
    for tc, (rc, rcu) in bounds.items():
        sigma = typecode_to_eph_m(tc)
        assert sigma is not None
        assert sigma * K95 >= max(rc, rcu) - 1e-9
    for tc in (18, 22, 19, 5, 31):
        assert typecode_to_eph_m(tc) is None


def _eph(dec: ModeSDecoder, *frames: str) -> float | None:
    """Feed frames, then one position; the eph_m of that position."""
    for f in frames:
        assert dec.feed_hex(f, 0.0) is None
    m = dec.feed_hex(position(), 0.0)
    assert m is not None
    return m.eph_m


def test_decoder_uses_nacp_when_known_and_the_containment_radius_before() -> None:
    dec = ModeSDecoder(*TOULOUSE)
    assert _eph(dec) == pytest.approx(185.2 / K95)  # TC 11, no NACp yet
    assert _eph(dec, tc31(10)) == pytest.approx(10.0 / K95)
    # Version 0 operational status has no NACp in those bits: ignored.
    assert _eph(dec, tc31(11, version=0)) == pytest.approx(10.0 / K95)
    assert _eph(dec, tc29(11)) == pytest.approx(3.0 / K95)
    # DO-260A target state (subtype 0) has another layout: ignored.
    assert _eph(dec, tc29(4, subtype=0)) == pytest.approx(3.0 / K95)
    assert _eph(dec, tc31(6, version=1)) == pytest.approx(555.6 / K95)
    # NACp 0 = unknown: back to the position's own bound.
    assert _eph(dec, tc31(0)) == pytest.approx(185.2 / K95)


def test_fallback_follows_the_position_type_code() -> None:
    dec = ModeSDecoder(*TOULOUSE)
    m = dec.feed_hex(position(9), 0.0)
    assert m is not None and m.eph_m == pytest.approx(7.5 / K95)
    m = dec.feed_hex(position(18), 0.0)
    assert m is not None and m.eph_m is None  # Rc unknown: the tracker's default applies


def _first_fix_variance(frames: list[str], config: TrackingConfig) -> float:
    """East-axis variance of a new ADS-B track after its first position."""
    dec = ModeSDecoder(*TOULOUSE)
    ms: list[Measurement] = []
    for f in frames:
        m = dec.feed_hex(f, 100.0)
        if m is not None:
            ms.append(m)
    assert len(ms) == 1
    tr = Tracker(LocalFrame(*TOULOUSE), config)
    assert tr.ingest(ms).accepted == 1
    return float(tr.covariance(TrackId(f"icao:{Icao24('48520a')}"))[0, 0])


def test_the_tracker_uses_the_nacp_sigma_as_measurement_noise() -> None:
    cfg = TrackingConfig(adsb_eph_m=15.0)
    # A new track starts with the measurement's own covariance: eph_m^2 per horizontal axis.
    assert _first_fix_variance([tc31(10), position()], cfg) == pytest.approx((10.0 / K95) ** 2)
    assert _first_fix_variance([tc31(7), position()], cfg) == pytest.approx((185.2 / K95) ** 2)
    assert _first_fix_variance([position(18)], cfg) == pytest.approx(15.0**2)
