"""MAVLink ``ADSB_VEHICLE`` (forwarded by a vehicle's or a ground receiver) -> Measurement.

Pure: the MAVLink adapter decodes the packet and calls :func:`adsb_vehicle_to_measurement`
with the message's fields, so this module does not import pymavlink.

Units on the wire: lat/lon degE7, altitude mm (``altitude_type`` 0 = pressure altitude
corrected to QNH, i.e. approximately AMSL; 1 = geometric/GNSS), heading cdeg (course over
ground), horizontal velocity cm/s, vertical velocity cm/s positive up, ``tslc`` whole seconds
since the receiver last heard the aircraft.
"""

from __future__ import annotations

from enum import IntFlag

from adapters.adsb.common import ground_velocity_ned_mps
from gcs_utm.model import Measurement, MeasurementSource, ModelError, normalise_icao24


class AdsbFlags(IntFlag):
    """MAVLink ``ADSB_FLAGS``."""

    VALID_COORDS = 1
    VALID_ALTITUDE = 2
    VALID_HEADING = 4
    VALID_VELOCITY = 8
    VALID_CALLSIGN = 16
    VALID_SQUAWK = 32
    SIMULATED = 64
    VERTICAL_VELOCITY_VALID = 128
    BARO_VALID = 256
    SOURCE_UAT = 32768


def adsb_vehicle_to_measurement(
    *,
    icao_address: int,
    lat_e7: int,
    lon_e7: int,
    altitude_type: int,
    altitude_mm: int,
    heading_cdeg: int,
    hor_velocity_cms: int,
    ver_velocity_cms: int,
    callsign: str | bytes,
    tslc_s: int,
    flags: int,
    receipt_t_s: float,
    link: str = "",
) -> Measurement | None:
    """The fields of one ``ADSB_VEHICLE`` -> a measurement, or ``None`` when the report has
    no valid position and altitude (flags), an ICAO address beyond 24 bits, or coordinates
    out of range. ``capture_t_s`` is ``receipt_t_s - tslc_s``. ``alt_amsl_m`` is the
    reported altitude in metres: QNH pressure altitude or geometric, per ``altitude_type``."""
    f = AdsbFlags(flags & 0xFFFF)
    if AdsbFlags.VALID_COORDS not in f or AdsbFlags.VALID_ALTITUDE not in f:
        return None
    if not 0 <= icao_address <= 0xFFFFFF:
        return None
    try:
        icao = normalise_icao24(f"{icao_address:06x}")
    except ModelError:
        return None
    lat = lat_e7 * 1e-7
    lon = lon_e7 * 1e-7
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        return None
    vel: tuple[float, float, float] | None = None
    if AdsbFlags.VALID_VELOCITY in f and AdsbFlags.VALID_HEADING in f:
        vel = ground_velocity_ned_mps(
            hor_velocity_cms / 100.0, heading_cdeg / 100.0, ver_velocity_cms / 100.0
        )
    if isinstance(callsign, bytes):
        callsign = callsign.decode("ascii", "replace")
    name = callsign.replace("\x00", "").strip() if AdsbFlags.VALID_CALLSIGN in f else ""
    return Measurement(
        source=MeasurementSource.ADSB,
        capture_t_s=receipt_t_s - max(0, tslc_s),
        receipt_t_s=receipt_t_s,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=altitude_mm / 1000.0,
        vel_ned_mps=vel,
        icao24=icao,
        link=link,
        callsign=name,
    )
