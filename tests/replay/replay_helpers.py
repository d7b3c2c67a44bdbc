"""Helpers for the replay tests: synthetic tlogs written with pymavlink directly (not our
encoder), so the replay path is checked against an independent MAVLink implementation."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.tlog import TlogWriter

T0_S = 1_700_000_000.0
LAT0, LON0, ALT0 = 40.4168, -3.7038, 700.0  # Madrid, 700 m AMSL
M_PER_DEG_LAT = 111_132.0


@dataclass(frozen=True)
class Leg:
    """A straight constant-speed path: east/north metres from the origin at t0 and velocity."""

    sys_id: int
    east0_m: float
    north0_m: float
    v_east_mps: float
    v_north_mps: float
    alt_amsl_m: float = ALT0 + 50.0

    def at(self, dt_s: float) -> tuple[float, float, float]:
        east = self.east0_m + self.v_east_mps * dt_s
        north = self.north0_m + self.v_north_mps * dt_s
        lat = LAT0 + north / M_PER_DEG_LAT
        lon = LON0 + east / (M_PER_DEG_LAT * math.cos(math.radians(LAT0)))
        return lat, lon, self.alt_amsl_m


# Two vehicles flying head-on along the east axis at 10 m/s, 600 m apart at t0: they meet at
# t0 + 30 s at the origin, same altitude.
CONVERGING = (
    Leg(sys_id=1, east0_m=-300.0, north0_m=0.0, v_east_mps=10.0, v_north_mps=0.0),
    Leg(sys_id=2, east0_m=300.0, north0_m=0.0, v_east_mps=-10.0, v_north_mps=0.0),
)
MEET_S = 30.0


def write_tlog(
    path: Path, legs: tuple[Leg, ...] = CONVERGING, duration_s: float = 40.0, hz: float = 5.0
) -> int:
    """Write HEARTBEAT (1 Hz, PX4 quadrotor) and GLOBAL_POSITION_INT (``hz``) of each leg;
    returns the number of GLOBAL_POSITION_INT records per vehicle."""
    encoders = {leg.sys_id: mav.MAVLink(None, srcSystem=leg.sys_id, srcComponent=1) for leg in legs}
    n = round(duration_s * hz)
    with TlogWriter(path) as w:
        for k in range(n):
            dt = k / hz
            for leg in legs:
                enc = encoders[leg.sys_id]
                t = T0_S + dt + 0.01 * leg.sys_id
                if k % round(hz) == 0:
                    hb = enc.heartbeat_encode(
                        mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, 129, 4 << 16 | 4 << 24, 4
                    )
                    w.write(t, hb.pack(enc))
                lat, lon, alt = leg.at(dt)
                gp = enc.global_position_int_encode(
                    int(dt * 1000) + 5000,
                    round(lat * 1e7),
                    round(lon * 1e7),
                    round(alt * 1000),
                    50_000,
                    round(leg.v_north_mps * 100),
                    round(leg.v_east_mps * 100),
                    0,
                    9000,
                )
                w.write(t + 0.001, gp.pack(enc))
    return n
