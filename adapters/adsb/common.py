"""Units and small helpers shared by the ADS-B decoders (pure, no I/O).

ADS-B carries feet, knots and feet per minute; the model carries metres and metres per second.
Altitudes: barometric reports are *pressure altitude* (ft, standard atmosphere 1013.25 hPa),
which we use as metres AMSL without a QNH correction; GNSS reports (ADS-B TC 20-22,
ADSB_VEHICLE ``altitude_type=1``) are geometric height. Each decoder says which it used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

FT_TO_M = 0.3048
KT_TO_MPS = 1852.0 / 3600.0
FPM_TO_MPS = FT_TO_M / 60.0

# 95 % horizontal radius of a circular normal = sigma * sqrt(-2 ln 0.05); NACp bounds are 95 %.
_EPU95_TO_SIGMA = 1.0 / math.sqrt(-2.0 * math.log(0.05))

# DO-260B Table 2-69: NACp -> estimated position uncertainty (95 %), metres.
_NACP_EPU95_M: dict[int, float] = {
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


# Horizontal containment radius Rc (m) of an airborne position by its type code: DO-260B
# NIC (Table 2-14); where the NIC supplement bits choose between two radii (TC 11, 13, 16),
# the larger. It also bounds ADS-B version 0's 95 % radius R_cu of the same type code
# (NUCp), so it is never optimistic whatever version the transponder speaks.
_TYPECODE_RC_M: dict[int, float] = {
    9: 7.5,
    10: 25.0,
    11: 185.2,
    12: 370.4,
    13: 1111.2,
    14: 1852.0,
    15: 3704.0,
    16: 14816.0,
    17: 37040.0,
    20: 7.5,
    21: 25.0,
}


def nacp_to_eph_m(nac_p: int | None) -> float | None:
    """NACp category -> 1-sigma horizontal accuracy in metres; ``None`` when unknown (0) or
    not a NACp (> 11). The bound is a 95 % radius (EPU); the tracker uses ``eph_m`` as the
    1-sigma of each horizontal axis, and a circular normal of that sigma puts 95 % inside
    ``sigma * sqrt(-2 ln 0.05)`` = 2.45 sigma."""
    if nac_p is None:
        return None
    epu = _NACP_EPU95_M.get(nac_p)
    return None if epu is None else epu * _EPU95_TO_SIGMA


def typecode_to_eph_m(typecode: int) -> float | None:
    """Fallback 1-sigma horizontal accuracy of an airborne position without a known NACp:
    its containment radius (see ``_TYPECODE_RC_M``) taken as a 95 % bound. Rc is an
    integrity bound (the error exceeds it with probability ~1e-7), so the 95 % error is
    inside it and the sigma is conservative. ``None`` for TC 18/22 (Rc unknown) and for
    type codes that are not airborne positions."""
    rc = _TYPECODE_RC_M.get(typecode)
    return None if rc is None else rc * _EPU95_TO_SIGMA


def ground_velocity_ned_mps(
    ground_speed_mps: float, track_deg: float, climb_mps: float
) -> tuple[float, float, float]:
    """Ground speed + true track (clockwise from north) + climb rate -> (north, east, down)."""
    track = math.radians(track_deg)
    return (
        ground_speed_mps * math.cos(track),
        ground_speed_mps * math.sin(track),
        -climb_mps,
    )


@dataclass(slots=True)
class AdsbCounters:
    """What a decoder saw. ``corrupt`` = malformed + crc_failed; nothing corrupt is emitted."""

    frames: int = 0
    malformed: int = 0
    crc_failed: int = 0
    not_adsb: int = 0
    positions: int = 0
    velocities: int = 0
    identifications: int = 0
    out_of_range: int = 0
    pending_cpr: int = 0
    aircraft_evicted: int = 0  # per-aircraft states forgotten (max_aircraft or idle)

    @property
    def corrupt(self) -> int:
        return self.malformed + self.crc_failed

    def as_dict(self) -> dict[str, int]:
        out = {f.name: int(getattr(self, f.name)) for f in fields(self)}
        out["corrupt"] = self.corrupt
        return out
