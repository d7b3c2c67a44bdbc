"""Traffic information to vehicles: ADSB_VEHICLE for the other aircraft near each vehicle.

PX4 (``NAV_TRAFF_AVOID``) and ArduPilot (``AVD_ENABLE``, AP_Avoidance, with ``ADSB_TYPE`` set)
act on ADSB_VEHICLE messages on their links, so relaying gcs-utm's picture makes the onboard
last line of defence work for traffic the vehicle cannot hear itself. Every
``1 / rate_hz`` s, each vehicle with a position gets one ADSB_VEHICLE per track within
``radius_m`` horizontally and ``max_height_diff_m`` vertically of it: other UAS (cooperative
tracks, ``sysid:`` and ``rid:`` tracks) and intruders (``icao:`` tracks), never its own track
(its operation's, or ``sysid:<its sysid>``), never a stale one.

Fields: position and altitude (geometric, AMSL) from the track (propagated to the round's
time, so ``tslc`` is 1 s), heading and speeds from its velocity. The ICAO address is the
intruder's own; an aircraft without one gets a stable made-up address with bit 24 set
(``SYNTHETIC_ICAO_BASE`` | 23 bits of the CRC-32 of its track id), outside the 24-bit ICAO
space: a vehicle that forwards its traffic list back to the GCS (ArduPilot does) echoes it,
and the hub's ADS-B relay drops such addresses instead of making a phantom intruder of them.
The callsign is the first 8 characters of the operation id or ICAO address; the emitter type
UAV (14) for UAS, unknown (0) otherwise.
"""

from __future__ import annotations

import asyncio
import logging
import math
import zlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol

from adapters.mavlink.transfer import MavlinkError, TransferError
from adapters.mavlink.vehicle import VehicleInfo, VehicleState
from gcs_utm.config import setting
from gcs_utm.geo import haversine_m
from gcs_utm.model import Operation, SysId, Track, TrackId

_log = logging.getLogger(__name__)

SYNTHETIC_ICAO_BASE = 0x1000000  # above the 24-bit ICAO space
_FLAGS = (
    1 | 2 | 4 | 8 | 16 | 128
)  # coords, altitude, heading, velocity, callsign, vertical velocity
_EMITTER_UAV = 14
_ALTITUDE_GEOMETRIC = 1


@dataclass(frozen=True, slots=True, kw_only=True)
class TrafficOutConfig:
    enabled: bool = setting(
        False,
        "send each vehicle ADSB_VEHICLE for the other UAS and intruders near it (for PX4 "
        "NAV_TRAFF_AVOID / ArduPilot AVD_ENABLE)",
    )
    rate_hz: float = setting(1.0, "rounds per second", min=0.1, max=10.0, unit="Hz")
    radius_m: float = setting(
        5000.0, "horizontal distance within which traffic is sent", min=10.0, unit="m"
    )
    max_height_diff_m: float = setting(
        1000.0, "vertical distance within which traffic is sent", min=10.0, unit="m"
    )


class TrafficHub(Protocol):
    def vehicles(self) -> list[VehicleInfo]: ...
    def state(self, vehicle: SysId) -> VehicleState: ...
    def send_raw(self, vehicle: SysId, name: str, *args: object) -> None: ...


@dataclass(slots=True)
class TrafficOutCounters:
    rounds: int = 0
    sent: int = 0  # ADSB_VEHICLE frames
    send_errors: int = 0


def icao_address(track: Track) -> int:
    """The track's ICAO address, or a stable made-up one (module docstring)."""
    if track.icao24:
        return int(track.icao24, 16)
    return SYNTHETIC_ICAO_BASE | (zlib.crc32(str(track.id).encode()) & 0x7FFFFF)


def own_track_ids(sys_id: int, operations: Iterable[Operation]) -> set[str]:
    own = {str(op.id) for op in operations if op.sys_id == sys_id}
    own.add(f"sysid:{sys_id}")
    return own


class TrafficOut:
    """See the module docstring."""

    def __init__(
        self,
        config: TrafficOutConfig,
        hub: TrafficHub,
        *,
        tracks: Callable[[], Mapping[TrackId, Track]],
        operations: Callable[[], Iterable[Operation]],
    ) -> None:
        self.config = config
        self.hub = hub
        self.counters = TrafficOutCounters()
        self._tracks = tracks
        self._operations = operations

    async def run(self) -> None:
        if not self.config.enabled:
            return
        while True:
            await asyncio.sleep(1.0 / self.config.rate_hz)
            self.tick()

    def tick(self) -> None:
        """One round: every vehicle with a position gets the traffic near it."""
        self.counters.rounds += 1
        tracks = [t for t in self._tracks().values() if not t.stale]
        ops = list(self._operations())
        seen: set[int] = set()
        for info in self.hub.vehicles():
            sid = info.key.sys_id
            if sid in seen:
                continue
            seen.add(sid)
            try:
                where = self.hub.state(SysId(sid)).last_position
            except MavlinkError:
                continue
            if where is None:
                continue
            own = own_track_ids(sid, ops)
            for t in tracks:
                if str(t.id) in own or str(t.id).startswith(f"sysid:{sid}@"):
                    continue
                if abs(t.alt_amsl_m - where.alt_amsl_m) > self.config.max_height_diff_m:
                    continue
                if haversine_m(where.lat_deg, where.lon_deg, t.lat_deg, t.lon_deg) > (
                    self.config.radius_m
                ):
                    continue
                self._send(SysId(sid), t)

    def _send(self, sid: SysId, t: Track) -> None:
        ve, vn, vu = t.vel_enu_mps
        heading_deg = math.degrees(math.atan2(ve, vn)) % 360.0
        callsign = (str(t.operation_id) if t.operation_id else str(t.icao24 or t.id))[:8]
        try:
            self.hub.send_raw(
                sid,
                "adsb_vehicle",
                icao_address(t),
                round(t.lat_deg * 1e7),
                round(t.lon_deg * 1e7),
                _ALTITUDE_GEOMETRIC,
                round(t.alt_amsl_m * 1000.0),
                round(heading_deg * 100.0) % 36000,
                min(65535, round(math.hypot(ve, vn) * 100.0)),
                max(-32768, min(32767, round(vu * 100.0))),
                callsign.encode("ascii", "replace"),
                0 if t.icao24 else _EMITTER_UAV,
                1,  # tslc: the track is propagated to now
                _FLAGS,
                0,
            )
        except (MavlinkError, TransferError, OSError) as exc:
            self.counters.send_errors += 1
            _log.debug("traffic to sysid %d not sent: %s", sid, exc)
            return
        self.counters.sent += 1
