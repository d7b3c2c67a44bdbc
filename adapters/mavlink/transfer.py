"""Mission and command exchanges with one vehicle (the hub's protocol half): the mission
upload and download state machines, MISSION_SET_CURRENT, COMMAND_LONG/COMMAND_INT with
retries, and waiting for a mode to show in HEARTBEAT.

:class:`Transfers` is a part the :class:`~adapters.mavlink.hub.MavlinkHub` holds. It is
passed the hub's link/dispatch core as a :class:`VehicleLink` (the vehicle table and the send
path) and owns the per-vehicle mailboxes: the hub's receive path hands protocol messages to
:meth:`Transfers.deliver` and wakes a waiting exchange with :meth:`Transfers.wake`. One
exchange per vehicle at a time (:meth:`Transfers.exchange` holds a per-vehicle lock).
Timeouts are real (loop) seconds: the vehicle's protocol timers run on its own clock,
whatever the simulation speed.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
import math
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Protocol

from adapters.mavlink import wire
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.mission import MissionItem
from adapters.mavlink.modes import set_mode_params
from adapters.mavlink.vehicle import VehicleState
from gcs_utm.clock import Clock
from gcs_utm.messages import FlightMode, VehicleKey
from gcs_utm.model import Position, SysId

_log = logging.getLogger(__name__)


def _loop_time() -> float:
    """The running loop's time: exchange timeouts are counted in the units the loop waits in
    (``time.monotonic()`` on an ordinary loop, simulated seconds on a fast-time loop)."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:  # no loop running (a synchronous caller): the same clock
        return time.monotonic()


MAV_MISSION_ACCEPTED = 0
MAV_MISSION_ERROR = 1
MAV_MISSION_INVALID_SEQUENCE = 13
MAV_MISSION_OPERATION_CANCELLED = 15
MAV_CMD_DO_SET_MODE = 176
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_IN_PROGRESS = 5
MAV_FRAME_GLOBAL = 0
_NAN = math.nan
_UPLOAD_WINDOW = 8  # at most this many items go out on one upload retry
_DOWNLOAD_RESTARTS = 2  # a download restarts on a refusal (MISSION_ACK) at most this often
MODE_CONFIRM_S = 3.0
"""How long a mode change may take to show in HEARTBEAT: heartbeats come at 1 Hz, so two
of them plus the command's round trip."""

Params7 = tuple[float, float, float, float, float, float, float]


class MavlinkError(RuntimeError):
    """A MAVLink operation that cannot start (unknown vehicle, hub closed)."""


class UploadFailure(enum.Enum):
    """Why an upload did not leave the vehicle flying the new mission."""

    NO_VEHICLE = "no_vehicle"  # never heard, or the link is closed
    REFUSED = "refused"  # the vehicle answered the upload with an error MISSION_ACK
    NO_ANSWER = "no_answer"  # the vehicle stopped answering the transfer
    DEADLINE = "deadline"  # the caller's deadline passed
    REBOOTED = "rebooted"  # the vehicle rebooted during the exchange
    READBACK_MISMATCH = "readback_mismatch"  # the vehicle's copy differs from what was sent
    CURRENT_NOT_SET = "current_not_set"  # MISSION_CURRENT never showed the intended item
    MODE_NOT_SET = "mode_not_set"  # the vehicle refused or did not enter mission mode


@dataclass(frozen=True, slots=True, kw_only=True)
class UploadResult:
    """The outcome of one upload (after its retry). ``ok``: the vehicle holds the mission
    (``verified``: its copy read back matched by meaning), its current item is the intended
    one (``current_set``, confirmed by MISSION_CURRENT) and, when asked, it is in mission
    mode (``mode_set``, confirmed by HEARTBEAT). Otherwise ``failure`` says what failed and
    ``error`` gives the detail; ``tries`` counts whole uploads (a failed one is retried
    once), ``attempts`` our retransmission rounds in the last one."""

    ok: bool
    verified: bool
    attempts: int
    items: int
    duration_s: float
    error: str = ""
    current_set: bool = False
    mode_set: bool = False
    failure: UploadFailure | None = None
    tries: int = 1
    current_seq: int | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class CommandResult:
    ok: bool
    result: int | None
    attempts: int
    error: str = ""


class TransferCounters(Protocol):
    uploads_failed: int
    uploads_verified: int
    mission_retries: int


class _Step:
    """Adaptive retransmission timeout of one transfer: starts at ``min_retry_s``, grows by
    half on every silent retry up to ``item_timeout_s``, back to 3 x the smoothed RTT (at least
    ``min_retry_s``) on progress. Loss on a radio link is mostly random, not congestion: a
    doubling backoff made a few consecutive losses cost more than the rest of the transfer."""

    def __init__(self, cfg: MavlinkConfig) -> None:
        self.lo = cfg.min_retry_s
        self.hi = max(cfg.item_timeout_s, cfg.min_retry_s)
        self.rto = self.lo
        self.srtt: float | None = None

    def progress(self, rtt_s: float) -> None:
        self.srtt = rtt_s if self.srtt is None else 0.875 * self.srtt + 0.125 * rtt_s
        self.rto = min(self.hi, max(self.lo, 3.0 * self.srtt))

    def backoff(self) -> None:
        self.rto = min(self.hi, self.rto * 1.5)


class TransferError(Exception):
    """A mission or command exchange failed; ``failure`` says how."""

    def __init__(self, message: str, failure: UploadFailure = UploadFailure.NO_ANSWER) -> None:
        super().__init__(message)
        self.failure = failure


class VehicleLink(Protocol):
    """What the exchanges need of the hub's link/dispatch core."""

    def state(self, vehicle: SysId | VehicleKey) -> VehicleState:
        """The vehicle's state; raises :class:`MavlinkError` for an unknown vehicle."""
        ...

    def encoder(self, st: VehicleState) -> wire.Encoder:
        """The encoder for frames to ``st`` (signed with its key, if it has one)."""
        ...

    def send_to(self, st: VehicleState, frame: bytes) -> None:
        """Send ``frame`` to where ``st`` was last heard; raises :class:`TransferError`
        when its link is closed."""
        ...


class Transfers:
    """Protocol exchanges; see the module docstring."""

    def __init__(
        self, link: VehicleLink, config: MavlinkConfig, clock: Clock, counters: TransferCounters
    ) -> None:
        self.link = link
        self.config = config
        self.clock = clock
        self.counters = counters
        self._mailbox: dict[int, asyncio.Queue[wire.MavMsg]] = {}  # by id(state)
        self._locks: dict[int, asyncio.Lock] = {}

    # --- the receive path's side (the hub calls these) --------------------------------------
    def deliver(self, st: VehicleState, m: wire.MavMsg) -> None:
        """A protocol message of ``st`` to the exchange waiting on it (dropped when none)."""
        box = self._mailbox.get(id(st))
        if box is not None:
            box.put_nowait(m)

    def wake(self, st: VehicleState) -> None:
        """Wake the exchange waiting on ``st`` (its link went down, it rebooted): it checks
        and fails."""
        box = self._mailbox.get(id(st))
        if box is not None:
            box.put_nowait(None)

    def busy(self, st: VehicleState) -> bool:
        """An exchange with ``st`` is in progress."""
        lock = self._locks.get(id(st))
        return lock is not None and lock.locked()

    def forget(self, st: VehicleState) -> None:
        """``st`` was evicted: drop its lock."""
        self._locks.pop(id(st), None)

    # --- exchanges ----------------------------------------------------------------------------
    def budget_s(self, deadline_t_s: float | None) -> float:
        """Real (loop) seconds left for a transfer."""
        budget = self.config.transfer_timeout_s
        if deadline_t_s is not None:
            left = deadline_t_s - self.clock.now_s()
            speed = self.clock.speed
            if left <= 0.0:
                return 0.0
            if math.isfinite(speed):
                budget = min(budget, left / speed)
        return budget

    @contextlib.asynccontextmanager
    async def exchange(self, st: VehicleState) -> AsyncIterator[asyncio.Queue[wire.MavMsg]]:
        """Hold ``st``'s exchange lock; yields the mailbox its protocol messages come to."""
        lock = self._locks.setdefault(id(st), asyncio.Lock())
        async with lock:
            box: asyncio.Queue[wire.MavMsg] = asyncio.Queue()
            self._mailbox[id(st)] = box
            try:
                yield box
            finally:
                self._mailbox.pop(id(st), None)

    @staticmethod
    async def _get(box: asyncio.Queue[wire.MavMsg], timeout_s: float) -> wire.MavMsg | None:
        try:
            return await asyncio.wait_for(box.get(), max(0.0, timeout_s))
        except TimeoutError:
            return None

    def _check(self, st: VehicleState, reboots: int, end: float) -> None:
        if st.reboots != reboots:
            raise TransferError("vehicle rebooted during the transfer", UploadFailure.REBOOTED)
        if _loop_time() >= end:
            raise TransferError("deadline passed", UploadFailure.DEADLINE)

    def _cancel(self, st: VehicleState) -> None:
        with contextlib.suppress(TransferError):
            self.link.send_to(
                st,
                self.link.encoder(st).mission_ack(
                    st.sys_id, st.key.comp_id, MAV_MISSION_OPERATION_CANCELLED
                ),
            )

    async def upload(
        self,
        st: VehicleState,
        box: asyncio.Queue[wire.MavMsg],
        items: list[MissionItem],
        end: float,
        reboots: int,
    ) -> int:
        """The vehicle drives an upload (it requests item by item and re-requests on its own
        timer: PX4 every 250 ms, ArduPilot every second), so on a lossy link a lost request
        would cost a whole vehicle timeout. On our own (RTT-adapted) timeout we therefore send
        every item the vehicle may be waiting for: from the last one it asked for (our answer
        may be the lost datagram) to one past the highest we sent (its request may be lost,
        and items sent ahead may have been taken), twice:
        PX4 silently ignores an item it did not expect, ArduPilot NACKs it with
        MAV_MISSION_INVALID_SEQUENCE and keeps receiving, so that NACK is not an error. The
        first answer to each request goes out once: a clean link sees no extra traffic.
        Returns 1 + the number of our timeouts."""
        up = _UploadState(self, st, items)
        up.send_count()
        try:
            while True:
                self._check(st, reboots, end)
                m = await self._get(box, min(up.sent_t + up.step.rto, end) - _loop_time())
                self._check(st, reboots, end)
                if m is None:
                    if up.on_silence():
                        return up.attempts
                    continue
                if getattr(m, "mission_type", 0) != 0:
                    continue
                mid = m._header.msgId
                if mid in (wire.MISSION_REQUEST_INT, wire.MISSION_REQUEST):
                    up.on_request(int(m.seq))
                elif mid == wire.MISSION_ACK and _upload_done(st, int(m.type), up.last_sent):
                    return up.attempts
        except TransferError:
            self._cancel(st)
            raise

    async def download_mission(
        self, sys_id: SysId | VehicleKey, *, deadline_t_s: float | None = None
    ) -> list[MissionItem]:
        """The vehicle's mission (MISSION_REQUEST_LIST). Raises :class:`MavlinkError`."""
        st = self.link.state(sys_id)
        end = _loop_time() + self.budget_s(deadline_t_s)
        async with self.exchange(st) as box:
            try:
                got = await self.download(st, box, end, st.reboots)
            except TransferError as exc:
                raise MavlinkError(f"download from {sys_id} failed: {exc}") from exc
        st.mission = got  # what the vehicle flies (its landing sequence is kept by uploads)
        return got

    async def download(
        self, st: VehicleState, box: asyncio.Queue[wire.MavMsg], end: float, reboots: int
    ) -> list[MissionItem]:
        """The vehicle's mission, read within a held :meth:`exchange` (``box``) by ``end``
        (loop time); raises :class:`TransferError`."""
        # drain protocol leftovers of the upload (late re-requests, duplicate ACKs)
        while not box.empty():
            box.get_nowait()
        down = _DownloadState(self, st)
        down.request()
        try:
            while True:
                self._check(st, reboots, end)
                m = await self._get(box, min(down.sent_t + down.step.rto, end) - _loop_time())
                self._check(st, reboots, end)
                if m is None:
                    down.on_silence()
                elif getattr(m, "mission_type", 0) == 0 and down.on_message(m):
                    return down.got
        except TransferError:
            self._cancel(st)
            raise

    async def set_current(
        self,
        st: VehicleState,
        box: asyncio.Queue[wire.MavMsg],
        seqs: range,
        end: float,
        reboots: int,
    ) -> int | None:
        """MISSION_SET_CURRENT(seqs.start) until MISSION_CURRENT reports a seq in ``seqs``
        (PX4 in mission mode runs a DO item at once and reports the waypoint after it);
        returns that seq, or None. Sent once, then again only after ``command_timeout_s``
        (growing by half per silent retry) without that MISSION_CURRENT: both autopilots
        answer at once, and a resend on the mission items' millisecond timeout put about 16
        requests on the link in 0.45 s after each upload."""
        enc = self.link.encoder(st)
        wait_s = self.config.command_timeout_s
        for _attempt in range(self.config.max_retries + 1):
            self.link.send_to(st, enc.mission_set_current(st.sys_id, st.key.comp_id, seqs.start))
            wait_end = min(end, _loop_time() + wait_s)
            while (left := wait_end - _loop_time()) > 0:
                self._check(st, reboots, end)
                m = await self._get(box, left)
                if m is not None and m._header.msgId == wire.MISSION_CURRENT and m.seq in seqs:
                    return int(m.seq)
            self._check(st, reboots, end)
            wait_s *= 1.5
        return None

    async def send_mode(
        self, sys_id: SysId | VehicleKey, mode: FlightMode, *, deadline_t_s: float | None = None
    ) -> CommandResult:
        st = self.link.state(sys_id)
        p = set_mode_params(st.autopilot, st.kind, mode)
        if p is None:
            return CommandResult(
                ok=False,
                result=None,
                attempts=0,
                error=f"{st.autopilot.value} has no mode {mode.value}",
            )
        params = (p[0], p[1], p[2], 0.0, 0.0, 0.0, 0.0)
        return await self.send_command_long(st, MAV_CMD_DO_SET_MODE, params, deadline_t_s)

    async def send_command_long(
        self,
        st: VehicleState,
        cmd: int,
        params: tuple[float, float, float, float, float, float, float],
        deadline_t_s: float | None,
    ) -> CommandResult:
        """COMMAND_LONG ``cmd`` to ``st`` until its COMMAND_ACK."""
        enc = self.link.encoder(st)
        return await self._command(
            st,
            cmd,
            lambda conf: enc.command_long(st.sys_id, st.key.comp_id, cmd, conf, params),
            deadline_t_s,
        )

    async def command_long(
        self,
        vehicle: SysId | VehicleKey,
        cmd: int,
        params: Params7,
        *,
        deadline_t_s: float | None = None,
    ) -> CommandResult:
        """One COMMAND_LONG until its COMMAND_ACK (arming, take-off, any MAV_CMD)."""
        try:
            st = self.link.state(vehicle)
        except MavlinkError as exc:
            return CommandResult(ok=False, result=None, attempts=0, error=str(exc))
        return await self.send_command_long(st, cmd, params, deadline_t_s)

    async def send_command_int(
        self,
        st: VehicleState,
        cmd: int,
        params: tuple[float, float, float, float],
        target: Position,
        deadline_t_s: float | None,
    ) -> CommandResult:
        """COMMAND_INT at ``target`` (frame MAV_FRAME_GLOBAL: altitude AMSL)."""
        enc = self.link.encoder(st)
        frame = enc.command_int(
            st.sys_id,
            st.key.comp_id,
            MAV_FRAME_GLOBAL,
            cmd,
            params,
            round(target.lat_deg * 1e7),
            round(target.lon_deg * 1e7),
            target.alt_amsl_m,
        )
        return await self._command(st, cmd, lambda _conf: frame, deadline_t_s)

    async def wait_mode(self, st: VehicleState, mode: FlightMode, timeout_s: float) -> bool:
        """True once the vehicle's HEARTBEAT shows ``mode`` (within ``timeout_s`` real s)."""
        end = _loop_time() + timeout_s
        while st.mode is not mode:
            if _loop_time() >= end:
                return False
            await asyncio.sleep(0.02)
        return True

    async def _command(
        self,
        st: VehicleState,
        cmd: int,
        build: Callable[[int], bytes],
        deadline_t_s: float | None,
    ) -> CommandResult:
        end = _loop_time() + self.budget_s(deadline_t_s)
        attempts = 0
        result: int | None = None
        async with self.exchange(st) as box:
            reboots = st.reboots
            try:
                for conf in range(self.config.command_retries + 1):
                    if _loop_time() >= end:
                        break
                    attempts += 1
                    self.link.send_to(st, build(min(conf, 255)))
                    wait_end = min(end, _loop_time() + self.config.command_timeout_s)
                    while (left := wait_end - _loop_time()) > 0:
                        self._check(st, reboots, end + 1.0)
                        m = await self._get(box, left)
                        if m is None or m._header.msgId != wire.COMMAND_ACK or m.command != cmd:
                            continue
                        result = int(m.result)
                        if result == MAV_RESULT_IN_PROGRESS:
                            wait_end = min(end, _loop_time() + self.config.command_timeout_s)
                            continue
                        ok = result == MAV_RESULT_ACCEPTED
                        return CommandResult(
                            ok=ok,
                            result=result,
                            attempts=attempts,
                            error="" if ok else command_result(result),
                        )
            except TransferError as exc:
                return CommandResult(ok=False, result=result, attempts=attempts, error=str(exc))
        return CommandResult(
            ok=False,
            result=result,
            attempts=attempts,
            error=f"no COMMAND_ACK after {attempts} attempts",
        )


class _UploadState:
    """Our side of one upload: what the vehicle asked for and what we sent (see
    Transfers.upload)."""

    def __init__(self, owner: Transfers, st: VehicleState, items: list[MissionItem]) -> None:
        self.owner = owner
        self.st = st
        self.items = items
        self.enc = owner.link.encoder(st)
        self.step = _Step(owner.config)
        self.attempts = 1
        self.sent_t = _loop_time()
        self.highest = -1  # highest item the vehicle has requested
        self.sent_hi = -1  # highest item we have sent (asked for or sent ahead)
        self.last_sent = False  # item n-1 went out
        self.silent = 0

    def _send_item(self, seq: int) -> None:
        st = self.st
        self.owner.link.send_to(
            st, self.enc.mission_item_int(st.sys_id, st.key.comp_id, self.items[seq])
        )

    def send_count(self) -> None:
        st = self.st
        self.owner.link.send_to(
            st, self.enc.mission_count(st.sys_id, st.key.comp_id, len(self.items))
        )
        self.sent_t = _loop_time()

    def on_silence(self) -> bool:
        """Our timeout: resend what the vehicle may wait for. True when the transfer should
        go to the readback (the last item went out and its ACK may be lost)."""
        n = len(self.items)
        self.silent += 1
        if self.silent > self.owner.config.max_retries:
            if self.last_sent:
                # the vehicle may have taken the last item and its ACK be lost (and not every
                # vehicle repeats it): the readback decides
                _log.debug("%s: no ACK of the last item; verifying", self.st.key)
                return True
            raise TransferError(
                f"no answer after {self.silent - 1} retries (last item requested "
                f"{self.highest if self.highest >= 0 else None})"
            )
        self.step.backoff()
        self.attempts += 1
        self.owner.counters.mission_retries += 1
        if self.highest < 0:
            self.send_count()
            return False
        # the vehicle expects one of highest .. sent_hi + 1
        top = min(n - 1, self.sent_hi + 1, self.highest + _UPLOAD_WINDOW - 1)
        for _ in range(2):  # twice, as the retries of download
            for seq in range(self.highest, top + 1):
                self._send_item(seq)
        self.sent_hi = max(self.sent_hi, top)
        self.last_sent = self.sent_hi == n - 1
        self.sent_t = _loop_time()
        return False

    def on_request(self, seq: int) -> None:
        n = len(self.items)
        if not 0 <= seq < n:
            _log.debug("vehicle asked for item %d of %d", seq, n)
            return
        if seq < self.highest:
            return  # overtaken by a later request (reordered or re-requested)
        if seq > self.highest:
            self.step.progress(_loop_time() - self.sent_t)
            self.highest = seq
            self.silent = 0
        self._send_item(seq)
        self.sent_hi = max(self.sent_hi, seq)
        self.last_sent = self.sent_hi == n - 1
        self.sent_t = _loop_time()


class _DownloadState:
    """Our side of one download (MISSION_REQUEST_LIST, then each item in turn; see
    Transfers.download)."""

    def __init__(self, owner: Transfers, st: VehicleState) -> None:
        self.owner = owner
        self.st = st
        self.enc = owner.link.encoder(st)
        self.step = _Step(owner.config)
        self.count: int | None = None
        self.got: list[MissionItem] = []
        self.silent = 0
        self.refusals = 0
        self.sent_t = _loop_time()

    def request(self) -> None:
        """Ask for what comes next: the list, then the next item."""
        st = self.st
        ts, tc = st.sys_id, st.key.comp_id
        if self.count is None:
            self.owner.link.send_to(st, self.enc.mission_request_list(ts, tc))
        else:
            self.owner.link.send_to(st, self.enc.mission_request_int(ts, tc, len(self.got)))
        self.sent_t = _loop_time()

    def on_silence(self) -> None:
        """Our timeout: ask again, twice -- a lost request or a lost answer costs a whole
        timeout, a duplicate costs one datagram (PX4 answers a repeated request for the item
        it just sent, ArduPilot answers any request)."""
        self.silent += 1
        if self.silent > self.owner.config.max_retries:
            raise TransferError(f"no answer to download after {self.silent - 1} retries")
        self.step.backoff()
        self.owner.counters.mission_retries += 1
        self.request()
        self.request()  # encoded anew: a signed frame is never replayed

    def on_message(self, m: wire.MavMsg) -> bool:
        """A mission message of the vehicle; True when the download is complete (and
        acknowledged)."""
        mid = m._header.msgId
        if mid == wire.MISSION_COUNT and self.count is None:
            self.count = int(m.count)
        elif mid == wire.MISSION_ITEM_INT and self.count is not None and m.seq == len(self.got):
            self.got.append(item_from(m))
        elif mid == wire.MISSION_ACK and m.type != MAV_MISSION_ACCEPTED:
            self.on_refusal(int(m.type))
            return False
        else:
            return False
        self.step.progress(_loop_time() - self.sent_t)
        self.silent = 0
        if self.count is not None and len(self.got) >= self.count:
            st = self.st
            self.owner.link.send_to(
                st, self.enc.mission_ack(st.sys_id, st.key.comp_id, MAV_MISSION_ACCEPTED)
            )
            return True
        self.request()
        return False

    def on_refusal(self, result: int) -> None:
        """A MISSION_ACK refusal: a late answer to an upload item repeated after the upload
        ended, or the vehicle dropped the transfer (PX4 does on a request it did not expect):
        start over; a vehicle that keeps refusing fails the download."""
        self.refusals += 1
        if self.refusals > _DOWNLOAD_RESTARTS:
            raise TransferError(f"vehicle refused the download: {mission_result(result)}")
        self.count = None
        self.got.clear()
        self.request()


def _upload_done(st: VehicleState, result: int, last_sent: bool) -> bool:
    """A MISSION_ACK during an upload: True when the upload is over (to be verified), False
    to go on; raises on a refusal."""
    if result == MAV_MISSION_ACCEPTED:
        return last_sent  # before the last item: a stale ACK of an earlier transfer
    if result == MAV_MISSION_INVALID_SEQUENCE:
        return False  # ArduPilot's answer to an item it did not ask for
    if result == MAV_MISSION_ERROR and last_sent:
        # ArduPilot answers a repeated last item with ERROR once the upload is complete (its
        # ACCEPTED was lost): the readback decides
        _log.debug("%s: ERROR after the last item; verifying by readback", st.key)
        return True
    raise TransferError(
        f"vehicle rejected the mission: {mission_result(result)}", UploadFailure.REFUSED
    )


def item_from(m: wire.MavMsg) -> MissionItem:
    return MissionItem(
        seq=int(m.seq),
        command=int(m.command),
        frame=int(m.frame),
        current=int(m.current),
        autocontinue=int(m.autocontinue),
        param1=float(m.param1),
        param2=float(m.param2),
        param3=float(m.param3),
        param4=float(m.param4),
        x=int(m.x),
        y=int(m.y),
        z=float(m.z),
        mission_type=int(getattr(m, "mission_type", 0)),
    )


_MISSION_RESULTS = {
    1: "ERROR",
    2: "UNSUPPORTED_FRAME",
    3: "UNSUPPORTED",
    4: "NO_SPACE",
    5: "INVALID",
    6: "INVALID_PARAM1",
    7: "INVALID_PARAM2",
    8: "INVALID_PARAM3",
    9: "INVALID_PARAM4",
    10: "INVALID_PARAM5_X",
    11: "INVALID_PARAM6_Y",
    12: "INVALID_PARAM7",
    13: "INVALID_SEQUENCE",
    14: "DENIED",
    15: "OPERATION_CANCELLED",
}
_COMMAND_RESULTS = {
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}


def mission_result(code: int) -> str:
    return f"MAV_MISSION_{_MISSION_RESULTS.get(code, str(code))}"


def command_result(code: int) -> str:
    return f"MAV_RESULT_{_COMMAND_RESULTS.get(code, str(code))}"
