"""SBS-1 BaseStation lines as dump1090 writes them on port 30003 (for tests)."""

from __future__ import annotations


def sbs_position(
    icao: str, lat_deg: float, lon_deg: float, alt_ft: float, *, callsign: str = ""
) -> str:
    """``MSG,3`` airborne position; the generated date/time left empty (capture = receipt)."""
    fields = ["MSG", "3", "1", "1", icao.upper(), "1", "", "", "", "", callsign, f"{alt_ft:.0f}"]
    fields += ["", "", f"{lat_deg:.5f}", f"{lon_deg:.5f}", "", "", "0", "0", "0", "0"]
    return ",".join(fields)


def sbs_velocity(icao: str, ground_speed_kt: float, track_deg: float, climb_fpm: float) -> str:
    """``MSG,4`` airborne velocity."""
    fields = ["MSG", "4", "1", "1", icao.upper(), "1", "", "", "", "", "", ""]
    fields += [f"{ground_speed_kt:.1f}", f"{track_deg:.1f}", "", "", f"{climb_fpm:.0f}"]
    fields += ["", "0", "0", "0", "0"]
    return ",".join(fields)
