"""ADS-B adapter: MAVLink ADSB_VEHICLE, SBS-1 BaseStation text, raw Mode-S (AVR text, Beast
binary) via pyModeS 3 -> :class:`gcs_utm.model.Measurement` with ``source=ADSB``.

Decoders are pure (no I/O) and never raise on bad input: they count it. Network readers live
in :mod:`adapters.adsb.net`.
"""

from adapters.adsb.beast import BeastCounters, BeastFrame, BeastFramer
from adapters.adsb.common import AdsbCounters, nacp_to_eph_m
from adapters.adsb.config import AdsbConfig
from adapters.adsb.errors import AdsbError, ModeSFrameError, SbsFormatError
from adapters.adsb.mavlink import AdsbFlags, adsb_vehicle_to_measurement
from adapters.adsb.modes import ModeSDecoder, parse_avr_line
from adapters.adsb.sbs import SbsDecoder, SbsRecord, decode_sbs_line, parse_sbs_line

__all__ = [
    "AdsbConfig",
    "AdsbCounters",
    "AdsbError",
    "AdsbFlags",
    "BeastCounters",
    "BeastFrame",
    "BeastFramer",
    "ModeSDecoder",
    "ModeSFrameError",
    "SbsDecoder",
    "SbsFormatError",
    "SbsRecord",
    "adsb_vehicle_to_measurement",
    "decode_sbs_line",
    "nacp_to_eph_m",
    "parse_avr_line",
    "parse_sbs_line",
]
