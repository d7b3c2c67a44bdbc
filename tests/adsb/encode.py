"""A small ADS-B (DF17 extended squitter) encoder for tests, and the generator of the
synthetic captures in ``tests/data/adsb`` (written by this project, Apache-2.0).

Encoding follows the ICAO Annex 10 Vol IV / DO-260B layouts as decoded by pyModeS: the 24-bit
Mode S parity (generator 0xFFF409), airborne position (TC 11, 25 ft altitude steps, 17-bit
CPR with NZ = 15), identification (TC 4) and airborne velocity (TC 19 subtype 1, knots and
64 ft/min steps). All-call replies (DF11) stand for the non-ADS-B Mode S a receiver hears.

Regenerate the data files (then review the diff; the tests state what they must contain):
``.venv/bin/python -m tests.adsb.encode``
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

_CHARSET = "#ABCDEFGHIJKLMNOPQRSTUVWXYZ##### ###############0123456789######"
FT = 0.3048
KT = 1852.0 / 3600.0
DATA = Path(__file__).resolve().parents[1] / "data" / "adsb"


def parity(data: bytes) -> int:
    """Mode S 24-bit parity of ``data`` (all but the last 3 bytes of a frame)."""
    crc = 0
    for byte in data:
        crc ^= byte << 16
        for _ in range(8):
            crc = ((crc << 1) ^ 0xFFF409) if crc & 0x800000 else crc << 1
            crc &= 0xFFFFFF
    return crc


def df17(icao: str, me: int) -> str:
    """A DF17 frame (capability 5) carrying the 56-bit ``me`` field, in hex."""
    body = bytes([0x8D]) + bytes.fromhex(icao) + me.to_bytes(7, "big")
    return (body + parity(body).to_bytes(3, "big")).hex().upper()


def df11(icao: str) -> str:
    """An all-call reply (DF11, interrogator 0: the parity field is the plain parity)."""
    body = bytes([0x5D]) + bytes.fromhex(icao)
    return (body + parity(body).to_bytes(3, "big")).hex().upper()


def beast(frame_hex: str, mlat_ticks: int, signal: int = 0x80) -> bytes:
    """One frame as dump1090 writes it on its Beast port: 0x1a, type '2' (short) or '3'
    (long), 6-byte MLAT counter, signal byte, payload; every 0x1a of the body doubled."""
    payload = bytes.fromhex(frame_hex)
    body = mlat_ticks.to_bytes(6, "big") + bytes([signal]) + payload
    kind = b"3" if len(payload) == 14 else b"2"
    return b"\x1a" + kind + body.replace(b"\x1a", b"\x1a\x1a")


def identification(icao: str, callsign: str) -> str:
    me = (4 << 51) | (0 << 48)  # TC 4, category 0
    for i, ch in enumerate(callsign.upper().ljust(8)[:8]):
        me |= _CHARSET.index(ch) << (42 - 6 * i)
    return df17(icao, me)


def _nl(lat_deg: float) -> int:
    """Number of CPR longitude zones at ``lat_deg``."""
    if lat_deg == 0.0:
        return 59
    if abs(lat_deg) >= 87.0:
        return 2 if abs(lat_deg) == 87.0 else 1
    a = 1.0 - math.cos(math.pi / 30.0)
    b = math.cos(math.radians(abs(lat_deg))) ** 2
    return math.floor(2.0 * math.pi / math.acos(1.0 - a / b))


def cpr(lat_deg: float, lon_deg: float, odd: bool) -> tuple[int, int]:
    """17-bit airborne CPR (lat, lon) of one position."""
    i = int(odd)
    dlat = 360.0 / (60 - i)
    yz = math.floor(2**17 * (lat_deg % dlat) / dlat + 0.5)
    rlat = dlat * (yz / 2**17 + math.floor(lat_deg / dlat))
    zones = _nl(rlat) - i
    dlon = 360.0 / zones if zones > 0 else 360.0
    xz = math.floor(2**17 * (lon_deg % dlon) / dlon + 0.5)
    return yz % 2**17, xz % 2**17


def position(icao: str, lat_deg: float, lon_deg: float, alt_ft: float, odd: bool) -> str:
    """Airborne position, barometric altitude (TC 11), even or odd CPR."""
    n = round((alt_ft + 1000.0) / 25.0)
    alt12 = ((n >> 4) << 5) | (1 << 4) | (n & 0xF)
    yz, xz = cpr(lat_deg, lon_deg, odd)
    me = (11 << 51) | (alt12 << 36) | (int(odd) << 34) | (yz << 17) | xz
    return df17(icao, me)


def velocity(icao: str, east_kt: float, north_kt: float, climb_fpm: float) -> str:
    """Airborne velocity over ground (TC 19 subtype 1), GNSS vertical rate."""
    v_ew, v_ns = round(abs(east_kt)) + 1, round(abs(north_kt)) + 1
    vr = round(abs(climb_fpm) / 64.0) + 1
    me = (19 << 51) | (1 << 48) | (1 << 43)  # subtype 1, NACv 1
    me |= (int(east_kt < 0) << 42) | (v_ew << 32) | (int(north_kt < 0) << 31) | (v_ns << 21)
    me |= (int(climb_fpm < 0) << 19) | (vr << 10)
    return df17(icao, me)


@dataclass(frozen=True, slots=True)
class Flight:
    """A straight, level flight: where it is ``t_s`` seconds after its start."""

    icao: str
    callsign: str
    lat_deg: float
    lon_deg: float
    alt_ft: float
    track_deg: float
    speed_kt: float

    def at(self, t_s: float) -> tuple[float, float]:
        d_m = self.speed_kt * KT * t_s
        north_m = d_m * math.cos(math.radians(self.track_deg))
        east_m = d_m * math.sin(math.radians(self.track_deg))
        lat = self.lat_deg + north_m / 111_320.0
        return lat, self.lon_deg + east_m / (111_320.0 * math.cos(math.radians(lat)))

    @property
    def velocity_kt(self) -> tuple[float, float]:
        rad = math.radians(self.track_deg)
        return self.speed_kt * math.sin(rad), self.speed_kt * math.cos(rad)


# The replacement for the GPL sample of pyModeS: one airliner at FL360 heading west-north-west
# near the Netherlands, 10 minutes.
CSV_FLIGHT = Flight("4ca7e9", "GCS1234", 52.10, 5.60, 36000.0, 290.0, 490.0)
CSV_T0_S = 1_700_000_000.0
CSV_DURATION_S = 600.0


def csv_frames() -> list[tuple[float, str]]:
    """(epoch, hex) of the synthetic CSV: a position every second (even and odd in turn), a
    velocity every second between them, the identification and an all-call reply every
    10 s."""
    f = CSV_FLIGHT
    east_kt, north_kt = f.velocity_kt
    rows: list[tuple[float, str]] = []
    for k in range(int(CSV_DURATION_S)):
        t = float(k)
        lat, lon = f.at(t)
        rows.append((CSV_T0_S + t, position(f.icao, lat, lon, f.alt_ft, odd=k % 2 == 1)))
        rows.append((CSV_T0_S + t + 0.5, velocity(f.icao, east_kt, north_kt, 0.0)))
        if k % 10 == 3:
            rows.append((CSV_T0_S + t + 0.25, identification(f.icao, f.callsign)))
        if k % 10 == 7:
            rows.append((CSV_T0_S + t + 0.75, df11(f.icao)))
    return sorted(rows)


# SBS-1 capture beside the shipped ArduSub tlog (48.386 N, 124.631 W, 2023-05-04 17:15:41 to
# 17:20:04 UTC): a floatplane crossing low over the ROV's position, and an airliner far off.
SBS_T0_S = 1683220545.0
SBS_DURATION_S = 240.0
SBS_FLIGHTS = (
    Flight("a4f3c2", "N7012F", 48.3800, -124.6600, 1200.0, 75.0, 110.0),
    Flight("c07b1e", "ACA551", 48.2500, -124.9000, 24000.0, 60.0, 430.0),
)


def _sbs_time(t_s: float) -> tuple[str, str]:
    import time

    whole = math.floor(t_s)
    ms = round((t_s - whole) * 1000.0)
    stamp = time.gmtime(whole)
    return time.strftime("%Y/%m/%d", stamp), time.strftime("%H:%M:%S", stamp) + f".{ms:03d}"


def _sbs(kind: int, f: Flight, t_s: float, **fields: str) -> str:
    date, clock = _sbs_time(t_s)
    out = ["MSG", str(kind), "1", "1", f.icao.upper(), "1", date, clock, date, clock]
    names = ("callsign", "alt", "gs", "track", "lat", "lon", "vr", "squawk")
    out += [fields.get(n, "") for n in names]
    out += ["", "", "", fields.get("ground", "0")]
    return ",".join(out)


def sbs_lines() -> list[str]:
    """dump1090-style SBS-1 lines of :data:`SBS_FLIGHTS`: positions (MSG,3) and velocities
    (MSG,4) every second, identification (MSG,1) and altitude replies (MSG,5/7) every 10 s,
    all-call replies (MSG,8) every 20 s."""
    lines: list[tuple[float, str]] = []
    for n, f in enumerate(SBS_FLIGHTS):
        for k in range(int(SBS_DURATION_S)):
            t = SBS_T0_S + k + 0.31 * n
            lat, lon = f.at(float(k))
            alt = f"{f.alt_ft:.0f}"
            lines.append((t, _sbs(3, f, t, alt=alt, lat=f"{lat:.5f}", lon=f"{lon:.5f}")))
            lines.append(
                (
                    t + 0.5,
                    _sbs(4, f, t + 0.5, gs=f"{f.speed_kt:.1f}", track=f"{f.track_deg:.1f}", vr="0"),
                )
            )
            if k % 10 == 0:
                lines.append((t + 0.2, _sbs(1, f, t + 0.2, callsign=f.callsign)))
                lines.append((t + 0.7, _sbs(5 + 2 * (k % 20 == 0), f, t + 0.7, alt=alt)))
            if k % 20 == 10:
                lines.append((t + 0.8, _sbs(8, f, t + 0.8)))
    return [line for _, line in sorted(lines)]


def main() -> None:
    with (DATA / "synthetic_adsb.csv").open("w") as out:
        for t, frame in csv_frames():
            out.write(f"{t:.3f},{frame}\n")
    (DATA / "synthetic_near_ardusub.sbs").write_text(
        "".join(f"{line}\r\n" for line in sbs_lines()), encoding="ascii"
    )


if __name__ == "__main__":
    main()
