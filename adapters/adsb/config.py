"""Settings of the ADS-B adapter (section ``[adsb]``).

The receiver position is the reference for single-frame CPR decoding (pyModeS ``reference=``):
it must lie within 180 NM of every aircraft it decodes, so positions farther than
``max_range_m`` from the receiver are dropped and counted, never emitted.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class AdsbConfig:
    enabled: bool = setting(
        False,
        "serve and run connect to the receiver feeds below (dump1090/readsb) and track what "
        "they decode; MAVLink ADSB_VEHICLE is tracked whatever this says",
    )
    receiver_position_known: bool = setting(
        False,
        "true: decode each airborne position frame at once against the receiver position; "
        "false: wait for even/odd CPR pairs (pyModeS PipeDecoder)",
    )
    receiver_lat_deg: float = setting(
        0.0, "receiver latitude (WGS84)", min=-90.0, max=90.0, unit="deg"
    )
    receiver_lon_deg: float = setting(
        0.0, "receiver longitude (WGS84)", min=-180.0, max=180.0, unit="deg"
    )
    max_range_m: float = setting(
        333_360.0,
        "positions farther than this from the receiver are dropped and counted "
        "(180 NM: the limit of reference-based CPR decoding)",
        min=1.0,
        max=1_000_000.0,
        unit="m",
    )
    velocity_max_age_s: float = setting(
        10.0,
        "a velocity report older than this is not attached to a new position",
        min=0.0,
        max=120.0,
        unit="s",
    )
    # Anybody in radio range (or on the feed's port) can send frames with any ICAO address,
    # so the decoders' per-aircraft state is bounded like the MAVLink hub's per-sender state.
    max_aircraft: int = setting(
        4096,
        "per feed: aircraft (ICAO addresses) whose decoder state is kept; when full, the "
        "least recently heard eighth is forgotten (counted in aircraft_evicted)",
        min=8,
        max=1_000_000,
    )
    aircraft_idle_s: float = setting(
        120.0,
        "per feed: an aircraft not heard for this long is forgotten (callsign, velocity, "
        "NACp, pending CPR frames; counted in aircraft_evicted)",
        min=1.0,
        max=86_400.0,
        unit="s",
    )
    host: str = setting("127.0.0.1", "host of the dump1090-style receiver feeds")
    # One feed per receiver: its SBS-1, AVR and Beast outputs carry the same aircraft, and
    # duplicated reports would make the tracker over-confident.
    sbs_port: int = setting(30003, "SBS-1 BaseStation text port (0: off)", min=0, max=65535)
    avr_port: int = setting(0, "AVR raw text port, 30002 on dump1090 (0: off)", min=0, max=65535)
    beast_port: int = setting(0, "Beast binary port, 30005 on dump1090 (0: off)", min=0, max=65535)
    reconnect_initial_s: float = setting(
        0.5, "first reconnect delay; doubles after each failure", min=0.01, max=60.0, unit="s"
    )
    reconnect_max_s: float = setting(
        30.0, "longest reconnect delay", min=0.01, max=3600.0, unit="s"
    )
    sbs_times_are_utc: bool = setting(
        True,
        "SBS 'message generated' date/time fields are UTC (dump1090-fa, readsb); "
        "false: use the receipt time as capture time",
    )
