"""Uploading a plan so that the vehicle flies it: transfer, readback verification by meaning,
current item, mission mode, one retry.

:class:`Uploads` is a part the :class:`~adapters.mavlink.hub.MavlinkHub` holds; it runs its
steps through the hub's :class:`~adapters.mavlink.transfer.Transfers` part.

One upload (:meth:`Uploads.upload_items`) is, for each try:
1. the mission protocol (:meth:`Transfers.upload`) until MISSION_ACK ACCEPTED;
2. the vehicle's copy downloaded back and compared item by item by what the autopilot is
   documented to keep (:func:`~adapters.mavlink.mission.same_item`);
3. the intended current item set with MISSION_SET_CURRENT and confirmed by MISSION_CURRENT
   (both PX4 and ArduPilot honour it; ArduPilot ignores the ``current`` flag of an upload).
   PX4 starts at the flagged item, a DO_CHANGE_SPEED included; ArduPilot at the navigation
   item after it (a DO item as current fails to restart), and the skipped speed item is then
   sent as a DO_CHANGE_SPEED command;
A plan (:meth:`Uploads.upload_plan`) sent to a vehicle whose mission (as last read from it:
download or readback) has a landing sequence (DO_LAND_START to the end, else the approach
and NAV_LAND / NAV_VTOL_LAND) keeps that sequence as the autopilot flies it: the plan's
waypoints that model the landing are replaced by the sequence itself, never sent as
waypoints (:mod:`adapters.mavlink.landing`): no UTM plan removes a pilot's landing.
4. with ``set_mission_mode``, DO_SET_MODE to the autopilot's mission mode (PX4 AUTO.MISSION,
   ArduPilot AUTO) until HEARTBEAT shows it -- only on an armed vehicle: on the ground the
   mode is the pilot's (it would override the mode the pilot takes off in).
A try that fails at any step is repeated once (ArduPilot refuses uploads with NO_SPACE for a
moment after boot; a lost datagram can fail a readback), unless the vehicle is unknown or the
deadline has passed. The result says which step failed (:class:`UploadFailure`).
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass

from adapters.mavlink.landing import plan_mission
from adapters.mavlink.loiter_kept import keep_loiters, mission_loiters
from adapters.mavlink.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MissionItem,
    is_nav,
    landing_sequence,
    plan_to_mission_items,
    same_item,
    start_item,
)
from adapters.mavlink.transfer import (
    MODE_CONFIRM_S,
    MavlinkError,
    TransferError,
    Transfers,
    UploadFailure,
    UploadResult,
    _loop_time,
)
from adapters.mavlink.vehicle import VehicleState
from gcs_utm.messages import FlightMode, VehicleKey
from gcs_utm.model import Autopilot, FlightPlan, Position, SysId, VehicleKind

_log = logging.getLogger(__name__)

UPLOAD_TRIES = 2  # a failed upload is retried once
RETRY_PAUSE_S = 1.0
"""Real seconds between the two tries: ArduPilot answers NO_SPACE for about a second after
boot while its mission storage initialises."""
_NO_RETRY = frozenset({UploadFailure.NO_VEHICLE, UploadFailure.DEADLINE})


@dataclass(slots=True)
class _Try:
    attempts: int = 0
    verified: bool = False
    current_seq: int | None = None
    mode_set: bool = False


class Uploads:
    """Plan and mission uploads (see the module docstring), run through ``transfers``."""

    def __init__(self, transfers: Transfers) -> None:
        self.transfers = transfers

    async def upload_plan(
        self,
        sys_id: SysId | VehicleKey,
        plan: FlightPlan,
        *,
        autopilot: Autopilot | None = None,
        start_index: int = 0,
        home: Position | None = None,
        deadline_t_s: float | None = None,
        set_mission_mode: bool = True,
        climb_rate_mps: float | None = None,
        descent_rate_mps: float | None = None,
        min_speed_mps: float = 0.0,
        lands: bool = False,
    ) -> UploadResult:
        """Upload ``plan`` as a mission, verify it, start it at plan waypoint ``start_index``
        (see :meth:`upload_items`); the vertical speeds let a climb on the spot keep the
        plan's time, and a fixed wing's speeds are airspeeds no lower than ``min_speed_mps``
        (see :func:`plan_to_mission_items`). ``lands``: the plan ends with a landing at its
        last waypoint (a multirotor's NAV_LAND there, in place of the landing sequence of the
        vehicle's mission; a fixed wing's plan is followed by that sequence). Never raises
        for vehicle behaviour: failures are in the result."""
        t0 = _loop_time()
        try:
            st = self.transfers.link.state(sys_id)
        except MavlinkError as exc:
            return _failed(0, 0, t0, (str(exc), UploadFailure.NO_VEHICLE), _Try())
        ap = autopilot or st.autopilot
        where = home or st.home
        home_alt_m = None if where is None else where.alt_amsl_m
        # an ArduPlane's loiters are sent as loiter items, not as their circle's points
        # (adapters/mavlink/loiter_kept.py)
        fw_ap = st.kind is VehicleKind.FIXED_WING and ap is Autopilot.ARDUPILOT
        loiters = mission_loiters(st.mission) if fw_ap else []

        def build(part: FlightPlan, start: int) -> list[MissionItem]:
            items = plan_to_mission_items(
                part,
                ap,
                home,
                start_index=start,
                max_speed_mps=self.transfers.config.max_speed_mps,
                climb_rate_mps=climb_rate_mps,
                descent_rate_mps=descent_rate_mps,
                kind=st.kind,
                min_speed_mps=min_speed_mps,
                lands=lands,
            )
            return keep_loiters(part, items, loiters, home_alt_m) if loiters else items

        # the pilot's landing sequence (last mission read from the vehicle) is flown as it is:
        # the plan's waypoints that model it are replaced by it (adapters/mavlink/landing.py)
        landing = landing_sequence(st.mission, ap)
        if lands and st.kind is not VehicleKind.FIXED_WING:
            # the plan brings its own NAV_LAND: the one of an earlier return home, left in the
            # vehicle's mission, is no pilot's sequence to rejoin (its approach is where that
            # return began its descent: the vehicle climbed back to it)
            landing = []
        items = plan_mission(
            plan,
            landing,
            build,
            start_index=start_index,
            kind=st.kind,
            home_alt_m=home_alt_m,
        )
        return await self.upload_items(
            st.key, items, deadline_t_s=deadline_t_s, set_mission_mode=set_mission_mode, _t0=t0
        )

    async def upload_items(
        self,
        vehicle: SysId | VehicleKey,
        items: list[MissionItem],
        *,
        deadline_t_s: float | None = None,
        set_mission_mode: bool = True,
        _t0: float | None = None,
    ) -> UploadResult:
        """Upload raw mission items; the item flagged ``current`` is the one to start at."""
        t0 = _loop_time() if _t0 is None else _t0
        end = t0 + self.transfers.budget_s(deadline_t_s)
        failure = UploadFailure.NO_VEHICLE
        errors: list[str] = []
        tried = _Try()
        for tries in range(1, UPLOAD_TRIES + 1):
            tried = _Try()
            try:
                st = self.transfers.link.state(vehicle)
                await self._try_upload(st, items, end, set_mission_mode, tried)
            except MavlinkError as exc:
                failure, error = UploadFailure.NO_VEHICLE, str(exc)
                errors.append(error)
            except TransferError as exc:
                failure, error = exc.failure, str(exc)
                errors.append(f"try {tries}: {error}")
            else:
                self.transfers.counters.uploads_verified += 1
                return UploadResult(
                    ok=True,
                    verified=True,
                    attempts=tried.attempts,
                    items=len(items),
                    duration_s=_loop_time() - t0,
                    current_set=True,
                    mode_set=tried.mode_set,
                    tries=tries,
                    current_seq=tried.current_seq,
                )
            _log.warning("upload to %s, try %d failed (%s): %s", vehicle, tries, failure, error)
            if failure in _NO_RETRY or tries == UPLOAD_TRIES:
                break
            await asyncio.sleep(max(0.0, min(RETRY_PAUSE_S, end - _loop_time() - 1.0)))
        self.transfers.counters.uploads_failed += 1
        return _failed(len(items), tries, t0, ("; ".join(errors), failure), tried)

    async def _try_upload(
        self,
        st: VehicleState,
        items: list[MissionItem],
        end: float,
        set_mission_mode: bool,
        tried: _Try,
    ) -> None:
        """One try; fills ``tried`` as it goes and raises TransferError on a failed step."""
        start, skipped_speed = start_item(items, st.autopilot)
        t = self.transfers
        async with t.exchange(st) as box:
            reboots = st.reboots
            tried.attempts = await t.upload(st, box, items, end, reboots)
            got = await t.download(st, box, end, reboots)
            self._verify_readback(st, items, got)
            st.mission = got
            tried.verified = True
            # PX4 in mission mode runs a DO item at once: MISSION_CURRENT may already show
            # the navigation item after it
            last = start
            while last < len(items) - 1 and not is_nav(items[last].command):
                last += 1
            seq = await t.set_current(st, box, range(start, last + 1), end, reboots)
            if seq is None:
                raise TransferError(
                    f"MISSION_CURRENT never showed item {start} (last seen {st.mission_seq})",
                    UploadFailure.CURRENT_NOT_SET,
                )
            tried.current_seq = seq
        if set_mission_mode and st.armed:
            await self._ensure_mission_mode(st, end)
            tried.mode_set = True
        elif set_mission_mode:  # never on the ground: the mode is the pilot's until take-off
            _log.info("%s: disarmed, mission mode not set after the upload", st.key)
        if skipped_speed is not None:
            p = skipped_speed
            res = await t.send_command_long(
                st,
                MAV_CMD_DO_CHANGE_SPEED,
                (p.param1, p.param2, p.param3, 0.0, 0.0, 0.0, 0.0),
                None,
            )
            if not res.ok:  # the leg is flown at the previous speed: late or early, not unsafe
                _log.warning("%s: leg speed of item %d not set: %s", st.key, p.seq, res.error)

    def _verify_readback(
        self, st: VehicleState, items: list[MissionItem], got: list[MissionItem]
    ) -> None:
        if len(got) != len(items):
            raise TransferError(
                f"readback has {len(got)} items, sent {len(items)}",
                UploadFailure.READBACK_MISMATCH,
            )
        for sent, back in zip(items, got, strict=True):
            if sent.seq == 0 and st.autopilot is Autopilot.ARDUPILOT:
                continue  # ArduPilot reports its own home at seq 0, not what we sent
            diff = same_item(sent, back, st.autopilot, st.kind)
            if diff:
                raise TransferError(
                    f"readback item {sent.seq} differs: {diff}", UploadFailure.READBACK_MISMATCH
                )

    async def _ensure_mission_mode(self, st: VehicleState, end: float) -> None:
        if st.mode is not FlightMode.MISSION:
            res = await self.transfers.send_mode(st.key, FlightMode.MISSION)
            if not res.ok:
                raise TransferError(
                    f"mission mode refused: {res.error}", UploadFailure.MODE_NOT_SET
                )
        wait_s = max(0.0, min(MODE_CONFIRM_S, end - _loop_time()))
        if not await self.transfers.wait_mode(st, FlightMode.MISSION, wait_s):
            raise TransferError(
                f"HEARTBEAT still shows {st.mode.value} after the mission mode was accepted",
                UploadFailure.MODE_NOT_SET,
            )


def _failed(
    n_items: int, tries: int, t0: float, why: tuple[str, UploadFailure], tried: _Try
) -> UploadResult:
    error, failure = why
    return UploadResult(
        ok=False,
        verified=tried.verified,
        attempts=tried.attempts,
        items=n_items,
        duration_s=_loop_time() - t0,
        error=error,
        current_set=tried.current_seq is not None,
        mode_set=tried.mode_set,
        failure=failure,
        tries=tries,
        current_seq=tried.current_seq,
    )
