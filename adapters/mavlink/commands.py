"""Safety commands (HOLD / RESUME / RTL / LAND / GOTO) mapped to what each autopilot does.

| command | PX4 | ArduCopter | ArduPlane |
|---|---|---|---|
| HOLD | AUTO.LOITER (DO_SET_MODE 4/3) | BRAKE (17) | LOITER (12) |
| RESUME | AUTO.MISSION (4/4) | AUTO (3) | AUTO (10) |
| RTL | AUTO.RTL (4/5) | RTL (6) | RTL (11) |
| LAND | MAV_CMD_NAV_LAND | LAND (9) | DO_LAND_START, else a landing mission |
| GOTO | DO_REPOSITION (COMMAND_INT) | same | same |

ArduCopter's LOITER follows the RC throttle, which without a transmitter sits at its minimum:
the copter descends to the ground; BRAKE holds position and altitude. ArduPlane answers
DO_LAND_START with MAV_RESULT_FAILED when its mission has no landing sequence, and refuses
MAV_CMD_NAV_LAND as a command (UNSUPPORTED), so the fallback uploads a two-item mission
(home, NAV_LAND ahead on the current track at the home's altitude), makes the NAV_LAND current
and switches to AUTO: the plane glides from where it is to the landing point. Not when
DO_LAND_START went unanswered and the mission (as last read) has a DO_LAND_START sequence:
ArduPlane may have started it, and the landing mission would replace the pilot's landing.
"""

from __future__ import annotations

import asyncio
import logging
import math

from adapters.mavlink.mission import (
    MAV_CMD_DO_LAND_START,
    MAV_CMD_NAV_LAND,
    MissionItem,
    landing_sequence,
)
from adapters.mavlink.transfer import CommandResult, MavlinkError, Transfers
from adapters.mavlink.upload import Uploads
from adapters.mavlink.vehicle import VehicleState
from gcs_utm.geo import haversine_m
from gcs_utm.messages import FlightMode, VehicleKey
from gcs_utm.model import Autopilot, Command, CommandKind, SysId, VehicleKind

_log = logging.getLogger(__name__)

MAV_CMD_DO_REPOSITION = 192
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
_NAN = math.nan
PLANE_GLIDE_RATIO = 15.0
"""Horizontal metres per metre of height to the fallback landing point: gentler than the
default landing glide of ArduPlane, so the approach never needs a steep descent."""
PLANE_MIN_APPROACH_M = 400.0  # shortest approach to the fallback landing point
_TRACK_SAMPLE_S = 0.3  # real seconds between the two positions that give the track


class Commands:
    """:meth:`send_command` (see the module docstring): a part the
    :class:`~adapters.mavlink.hub.MavlinkHub` holds, sending through its ``transfers`` and
    (for ArduPlane's landing mission) ``uploads`` parts."""

    def __init__(self, transfers: Transfers, uploads: Uploads) -> None:
        self.transfers = transfers
        self.uploads = uploads

    async def send_command(
        self,
        sys_id: SysId | VehicleKey,
        command: Command,
        *,
        deadline_t_s: float | None = None,
    ) -> CommandResult:
        """HOLD / RESUME / RTL / LAND / GOTO mapped to the vehicle's autopilot."""
        try:
            st = self.transfers.link.state(sys_id)
        except MavlinkError as exc:
            return CommandResult(ok=False, result=None, attempts=0, error=str(exc))
        kind = command.kind
        mode = {
            CommandKind.HOLD: FlightMode.HOLD,
            CommandKind.RESUME: FlightMode.MISSION,
            CommandKind.RTL: FlightMode.RTL,
        }.get(kind)
        if mode is not None:
            return await self.transfers.send_mode(st.key, mode, deadline_t_s=deadline_t_s)
        if kind is CommandKind.LAND:
            return await self._land(st, deadline_t_s)
        target = command.target
        if target is None:
            return CommandResult(ok=False, result=None, attempts=0, error="GOTO needs a target")
        # DO_REPOSITION: speed -1 (default), flag CHANGE_MODE (switch to guided/hold), yaw NaN
        return await self.transfers.send_command_int(
            st, MAV_CMD_DO_REPOSITION, (-1.0, 1.0, 0.0, _NAN), target, deadline_t_s
        )

    async def _land(self, st: VehicleState, deadline_t_s: float | None) -> CommandResult:
        if st.autopilot is not Autopilot.ARDUPILOT:
            params = (0.0, 0.0, 0.0, _NAN, _NAN, _NAN, _NAN)
            return await self.transfers.send_command_long(
                st, MAV_CMD_NAV_LAND, params, deadline_t_s
            )
        if st.kind is not VehicleKind.FIXED_WING:
            return await self.transfers.send_mode(
                st.key, FlightMode.LAND, deadline_t_s=deadline_t_s
            )
        res = await self.transfers.send_command_long(
            st, MAV_CMD_DO_LAND_START, (0.0,) * 7, deadline_t_s
        )
        if res.ok:
            return res
        if res.result is None and _lands(st):
            # no answer (it may have started it) and the pilot's landing sequence is on the
            # vehicle: a landing mission would replace it (no plan removes a pilot's landing)
            _log.warning(
                "%s: DO_LAND_START unanswered (%s): landing sequence kept", st.key, res.error
            )
            return CommandResult(
                ok=False,
                result=None,
                attempts=res.attempts,
                error=f"DO_LAND_START: {res.error}; the mission's landing sequence kept",
            )
        _log.warning("%s: DO_LAND_START failed (%s): landing mission instead", st.key, res.error)
        return await self._plane_land_here(st, res, deadline_t_s)

    async def _plane_land_here(
        self, st: VehicleState, land_start: CommandResult, deadline_t_s: float | None
    ) -> CommandResult:
        first = st.last_position
        if first is None:
            return CommandResult(
                ok=False,
                result=land_start.result,
                attempts=land_start.attempts,
                error=f"DO_LAND_START: {land_start.error}; no position for a landing mission",
            )
        await asyncio.sleep(_TRACK_SAMPLE_S)
        now = st.last_position or first
        moved_m = haversine_m(first.lat_deg, first.lon_deg, now.lat_deg, now.lon_deg)
        track_deg = _bearing_deg(first.lat_deg, first.lon_deg, now.lat_deg, now.lon_deg)
        height_m = now.alt_amsl_m - await self._home_alt_amsl_m(st, now.alt_amsl_m)
        dist_m = max(PLANE_MIN_APPROACH_M, PLANE_GLIDE_RATIO * height_m)
        lat, lon = _ahead(now.lat_deg, now.lon_deg, track_deg if moved_m > 1.0 else 0.0, dist_m)
        items = [
            MissionItem(
                seq=0,
                command=16,
                x=round(now.lat_deg * 1e7),
                y=round(now.lon_deg * 1e7),
                z=now.alt_amsl_m,
            ),
            MissionItem(
                seq=1,
                command=MAV_CMD_NAV_LAND,
                frame=MAV_FRAME_GLOBAL_RELATIVE_ALT,
                current=1,
                x=round(lat * 1e7),
                y=round(lon * 1e7),
                z=0.0,  # the home's altitude
            ),
        ]
        up = await self.uploads.upload_items(st.key, items, deadline_t_s=deadline_t_s)
        error = f"DO_LAND_START: {land_start.error}; landing mission {dist_m:.0f} m ahead"
        if not up.ok:
            error += f" failed: {up.error}"
        return CommandResult(ok=up.ok, result=None, attempts=land_start.attempts + 1, error=error)

    async def _home_alt_amsl_m(self, st: VehicleState, default_m: float) -> float:
        """ArduPilot's home altitude: its mission item 0 (``default_m`` when unreadable)."""
        try:
            items = await self.transfers.download_mission(st.key)
        except MavlinkError as exc:
            _log.warning("%s: home not read (%s)", st.key, exc)
            return default_m
        return items[0].z if items and items[0].x != 0 else default_m


def _lands(st: VehicleState) -> bool:
    """Whether the vehicle's mission (as last read from it) has a DO_LAND_START sequence."""
    sequence = landing_sequence(st.mission, st.autopilot)
    return bool(sequence) and sequence[0].command == MAV_CMD_DO_LAND_START


def _ahead(lat_deg: float, lon_deg: float, track_deg: float, dist_m: float) -> tuple[float, float]:
    """The point ``dist_m`` along ``track_deg`` (local flat earth: a few km at most)."""
    r_m = 6_371_000.0
    t = math.radians(track_deg)
    dlat = math.degrees(dist_m * math.cos(t) / r_m)
    dlon = math.degrees(dist_m * math.sin(t) / (r_m * math.cos(math.radians(lat_deg))))
    return lat_deg + dlat, lon_deg + dlon


def _bearing_deg(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Initial great-circle bearing from point 1 to point 2, degrees from north."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(lon2 - lon1)
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0
