"""MavlinkHub: links, vehicle discovery, telemetry routing, mission upload/download, commands.

Threading model: everything runs on the asyncio loop; receive callbacks parse and dispatch
synchronously (no per-frame task), protocol exchanges (upload, download, commands) are
coroutines that wait on a per-vehicle mailbox with timeouts. A bad frame is counted in
:attr:`MavlinkHub.counters` and logged at debug level; nothing from the wire raises into the
loop.

Identity: a vehicle is (link, source address, sysid, compid) = :class:`VehicleKey`; API calls
take a ``SysId`` (resolved to its most recently heard component) or a ``VehicleKey``. Replies
are unicast to the address the vehicle was last heard from. A system id is bound to the link
and address it was first heard on; another sender claiming it is dropped, counted and reported
as a SPOOFING_ATTACK hazard instead of taking it over; system id 0 is never a vehicle; with a
key in ``signing_keys`` a vehicle's frames must be signed with it (see
:mod:`adapters.mavlink.senders`, :mod:`adapters.mavlink.signing`). Per-sender state is capped
and forgotten when idle (``max_senders``, ``max_vehicles``, ``sender_idle_s``).

Links: a TCP or serial link that is down (not up yet at start, or closed by the peer) is
reopened with backoff (``reconnect_min_s`` .. ``reconnect_max_s``); while it is down each of its
vehicles is reported with a COMMUNICATION_FAILURE hazard, and on reconnect ArduPilot vehicles
are asked for their streams again (docs/links-and-security.md).

Positions: with a sink that offers a :class:`~gcs_utm.model.PositionLane` (the USM), each
GLOBAL_POSITION_INT becomes one lane entry instead of a Measurement, and the lane is handed to
the sink after every UDP read burst, every 16 reports within a long burst and after every
stream chunk (:meth:`MavlinkHub.flush_positions`). Other sinks get Measurements.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Protocol

from adapters.mavlink import wire
from adapters.mavlink.adsb_relay import AdsbRelay, MessageHandler
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.endpoint import parse_endpoint
from adapters.mavlink.mission import MissionItem, current_seq, plan_to_mission_items, same_item
from adapters.mavlink.modes import set_mode_params
from adapters.mavlink.senders import Senders, idle_keys, over_cap_keys
from adapters.mavlink.signing import SignatureCheck
from adapters.mavlink.transport import Address, Backoff, Transport
from adapters.mavlink.vehicle import VehicleInfo, VehicleState
from gcs_utm.clock import Clock
from gcs_utm.messages import FlightMode, HazardReport, LinkHealth, VehicleKey, VehicleStatus
from gcs_utm.model import (
    LANE_STRIDE,
    Autopilot,
    Command,
    CommandKind,
    FlightPlan,
    Measurement,
    Position,
    PositionLane,
    SysId,
    ThreatKind,
    VehicleKind,
)
from gcs_utm.ratelog import RateLimitedLog

_log = logging.getLogger(__name__)

RawTap = Callable[[str, bytes, float], None]

MAV_MISSION_ACCEPTED = 0
MAV_MISSION_ERROR = 1
MAV_MISSION_INVALID_SEQUENCE = 13
MAV_MISSION_OPERATION_CANCELLED = 15
MAV_CMD_NAV_LAND = 21
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_LAND_START = 189
MAV_CMD_DO_REPOSITION = 192
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_IN_PROGRESS = 5
MAV_FRAME_GLOBAL = 0
MAV_DATA_STREAM_ALL = 0
_NAN = math.nan
_UPLOAD_WINDOW = 8  # at most this many items go out on one upload retry
_DOWNLOAD_RESTARTS = 2  # a download restarts on a refusal (MISSION_ACK) at most this often
_PROTOCOL_IDS = frozenset(
    {
        wire.MISSION_REQUEST,
        wire.MISSION_REQUEST_INT,
        wire.MISSION_ACK,
        wire.MISSION_COUNT,
        wire.MISSION_ITEM_INT,
        wire.MISSION_ITEM,
        wire.MISSION_CURRENT,
        wire.COMMAND_ACK,
    }
)
# Mailbox consumers read ``m._header``: protocol messages must stay pymavlink objects.
assert not _PROTOCOL_IDS.intersection(wire.FAST_IDS), "protocol messages on the fast path"
_ARDUPILOT_STREAM_MSGS = (
    wire.GLOBAL_POSITION_INT,
    wire.GPS_RAW_INT,
    wire.SYS_STATUS,
    wire.SYSTEM_TIME,
    wire.MISSION_CURRENT,
    wire.EXTENDED_SYS_STATE,
    wire.HOME_POSITION,
)


_LANE_HANDOVER = 16 * LANE_STRIDE
"""Lane entries are handed to the sink after each read burst, and also once this many
numbers (16 reports) wait: a burst of 64 datagrams takes 1-3 ms to read, and tracking should
not wait for its end (see MavlinkHub.flush_positions)."""


_DROPS_REPORT_S = 60.0  # a summary of refused and forgotten senders at most this often
_REFUSALS = frozenset(
    {"bad_signature", "unsigned", "replayed", "sysid_zero", "sysid_claims", "address_changes"}
)
_DROP_COUNTERS = (*sorted(_REFUSALS), "senders_evicted", "vehicles_evicted", "links_down")


class MavlinkError(RuntimeError):
    """A MAVLink operation that cannot start (unknown vehicle, hub closed)."""


class TelemetrySink(Protocol):
    def on_measurement(self, m: Measurement) -> None: ...
    def on_status(self, s: VehicleStatus) -> None: ...
    def on_hazard(self, h: HazardReport) -> None: ...
    def on_vehicle(self, v: VehicleInfo) -> None: ...
    def on_link_health(self, h: LinkHealth) -> None: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class UploadResult:
    """``verified`` only when the vehicle's copy, downloaded back, matched item by item."""

    ok: bool
    verified: bool
    attempts: int
    items: int
    duration_s: float
    error: str = ""
    current_set: bool = False
    mode_set: bool = False


@dataclass(frozen=True, slots=True, kw_only=True)
class CommandResult:
    ok: bool
    result: int | None
    attempts: int
    error: str = ""


@dataclass(slots=True)
class HubCounters:
    datagrams: int = 0
    bytes: int = 0
    frames: int = 0
    bad_crc: int = 0
    garbage: int = 0
    unknown_msg: int = 0
    truncated: int = 0
    bad_signature: int = 0
    not_for_us: int = 0
    address_changes: int = 0
    sysid_collisions: int = 0
    handler_errors: int = 0
    send_errors: int = 0
    uploads_failed: int = 0
    uploads_verified: int = 0
    mission_retries: int = 0  # our own timeouts in mission transfers (upload, readback)
    # per-sender bookkeeping and sender checks (see the module docstring)
    senders_evicted: int = 0
    vehicles_evicted: int = 0
    sysid_zero: int = 0
    sysid_claims: int = 0
    unsigned: int = 0  # frames of a keyed vehicle without a signature
    replayed: int = 0  # frames of a keyed vehicle with an old signing timestamp
    links_down: int = 0  # times a stream link went down
    dropped_link_down: int = 0  # frames not sent because their link was down

    def snapshot(self) -> dict[str, int]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(slots=True)
class _Link:
    name: str
    transport: Transport
    parsers: dict[Address | None, wire.Parser] = field(default_factory=dict)
    counters: wire.ParseCounters = field(default_factory=wire.ParseCounters)
    encoder: wire.Encoder | None = None
    peers: dict[Address, float] = field(default_factory=dict)  # vehicles' addresses
    seen: dict[Address | None, float] = field(default_factory=dict)  # any sender's last chunk
    fused: bool = False  # datagram link with the fast decode: position reports fused


@dataclass(frozen=True, slots=True, kw_only=True)
class LinkState:
    """One link as the hub sees it (:meth:`MavlinkHub.links`)."""

    name: str
    up: bool
    connects: int  # successful opens of a stream link (reconnects = connects - 1)
    failures: int  # failed opens in a row
    dropped_down: int  # frames not sent while down
    senders: int  # source addresses with parser state
    last_error: str


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


class _TransferError(Exception):
    pass


class MavlinkHub:
    """See the module docstring. Use ``async with MavlinkHub(...)`` or start()/close()."""

    def __init__(
        self,
        config: MavlinkConfig,
        clock: Clock,
        sink: TelemetrySink,
        raw_tap: RawTap | None = None,
    ) -> None:
        self.config = config
        self.clock = clock
        self.sink = sink
        self.raw_tap = raw_tap
        self.counters = HubCounters()
        # A sink that takes positions in columns (the USM: ``position_lane`` and
        # ``on_position_lane``) gets GLOBAL_POSITION_INT as lane entries, handed over after
        # each read (a UDP burst, a stream chunk) instead of one Measurement call per report.
        self._lane: PositionLane | None = getattr(sink, "position_lane", None)
        self._lane_ready: Callable[[], None] | None = getattr(sink, "on_position_lane", None)
        if self._lane is None or self._lane_ready is None:
            self._lane = self._lane_ready = None
        self._lane_values: list[float] = self._lane.values if self._lane is not None else []
        self._links: dict[str, _Link] = {}
        self._mailbox: dict[int, asyncio.Queue[wire.MavMsg]] = {}
        self._locks: dict[int, asyncio.Lock] = {}
        # repeated warnings: at most one line per cause per interval of clock time
        self._ratelog = RateLimitedLog(_log, config.warn_interval_s, now=clock.now_s)
        self._senders = Senders(config, sink, self._lane, self._busy, self._ratelog)
        self._senders.on_forget.append(self._forgotten)
        # the same tables under the names the protocol code uses
        self._states = self._senders.states
        self._by_sysid = self._senders.by_sysid
        self._addr = self._senders.addr  # id(state) -> last source address
        self._signers: dict[int, wire.Encoder] = {}
        self._keys: dict[int, bytes] = {}
        for sid, hexkey in config.signing_keys.items():
            try:
                self._keys[int(sid)] = wire.parse_key(hexkey)
            except ValueError as exc:
                raise MavlinkError(f"[mavlink] signing_keys.{sid}: {exc}") from exc
        # signing timestamps are UTC: the clock's (tlog time in a replay)
        self._verify = SignatureCheck(self._keys, now=clock.now_s) if self._keys else None
        self._claim_alerts: dict[int, float] = {}  # sysid -> when its last claim was reported
        self._restream: set[int] = set()  # id(state) of ArduPilot vehicles to ask for streams
        self._drops_reported: tuple[float, dict[str, int]] = (clock.now_s(), {})
        self._tasks: list[asyncio.Task[None]] = []
        self._handlers: dict[int, MessageHandler] = {
            wire.HEARTBEAT: VehicleState.on_heartbeat,
            wire.GLOBAL_POSITION_INT: VehicleState.on_global_position,
            wire.GPS_RAW_INT: VehicleState.on_gps_raw,
            wire.SYS_STATUS: VehicleState.on_sys_status,
            wire.BATTERY_STATUS: VehicleState.on_battery_status,
            wire.MISSION_CURRENT: VehicleState.on_mission_current,
            wire.EXTENDED_SYS_STATE: VehicleState.on_extended_sys_state,
            wire.STATUSTEXT: VehicleState.on_statustext,
            wire.SYSTEM_TIME: VehicleState.on_system_time,
            wire.HOME_POSITION: VehicleState.on_home_position,
        }
        self.adsb_relay = AdsbRelay()  # ADSB_VEHICLE relayed by a vehicle -> ADS-B measurement
        self._handlers[wire.ADSB_VEHICLE] = self.adsb_relay.on_adsb_vehicle

    # --- lifecycle ------------------------------------------------------------------------
    async def __aenter__(self) -> MavlinkHub:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def start(self) -> None:
        """Open every configured link and start the heartbeat and health tasks."""
        for text in self.config.links:
            await self.add_link(text)
        self._ensure_tasks()

    def _ensure_tasks(self) -> None:
        if not self._tasks:
            self._tasks = [
                asyncio.create_task(self._heartbeat_loop(), name="mavlink-heartbeat"),
                asyncio.create_task(self._health_loop(), name="mavlink-health"),
            ]

    async def add_link(self, endpoint: str) -> str:
        """Open one link; returns its name once bound (see :meth:`local_port`). A TCP or
        serial link whose peer is not there yet is returned all the same, and opened in the
        background with backoff (module docstring: Links)."""
        ep = parse_endpoint(endpoint)
        cfg = self.config
        transport = Transport(ep, Backoff(min_s=cfg.reconnect_min_s, max_s=cfg.reconnect_max_s))
        name = str(ep)
        base, n = name, 1
        while name in self._links:
            n += 1
            name = f"{base}#{n}"
        link = _Link(
            name=name, transport=transport, fused=transport.datagram and self.config.fast_decode
        )
        link.encoder = wire.Encoder(self.config.gcs_sys_id, self.config.gcs_comp_id)
        self._links[name] = link
        try:
            await transport.open(
                functools.partial(self._on_chunk, link),  # (data, addr), no Python frame
                self.config.udp_rcvbuf_bytes,
                self.config.udp_batch,
                self.flush_positions,
                functools.partial(self._link_state, link),
            )
        except BaseException:
            del self._links[name]
            transport.close()
            raise
        if transport.datagram and ep.kind.value != "udpin":
            self._send(link, link.encoder.heartbeat(), None)  # make the far end talk to us
        self._ensure_tasks()
        if transport.up:
            _log.info("link %s open (local port %d)", name, transport.local_port)
        return name

    def _link_state(self, link: _Link, up: bool) -> None:
        """A stream link came up or went down (transport callback)."""
        if up:
            assert link.encoder is not None
            self._send(link, link.encoder.heartbeat(), None)  # make the far end talk to us
            return
        self.counters.links_down += 1
        link.parsers.clear()  # a frame cut by the disconnect must not prefix the next stream
        t = self.clock.now_s()
        reason = link.transport.last_error
        for st in self._senders.on_link(link.name):
            if st.autopilot is Autopilot.ARDUPILOT:
                self._restream.add(id(st))  # a restarted ArduPilot sends nothing unasked
            box = self._mailbox.get(id(st))
            if box is not None:
                box.put_nowait(None)  # wake a transfer: its frames cannot go out
            if st.info is None:
                continue
            self.sink.on_hazard(
                st.hazard(ThreatKind.COMMUNICATION_FAILURE, t, f"link {link.name} down: {reason}")
            )

    def links(self) -> list[LinkState]:
        """The state of every link (up, reconnects, frames dropped while down)."""
        return [
            LinkState(
                name=lk.name,
                up=lk.transport.up,
                connects=lk.transport.connects,
                failures=lk.transport.failures,
                dropped_down=lk.transport.dropped_down,
                senders=len(lk.parsers),
                last_error=lk.transport.last_error,
            )
            for lk in self._links.values()
        ]

    def local_port(self, link: str) -> int:
        return self._links[link].transport.local_port

    def rcvbuf_bytes(self, link: str) -> int:
        """The UDP receive buffer the kernel granted ``link`` (0 for TCP and serial)."""
        return self._links[link].transport.rcvbuf_bytes

    def link_names(self) -> tuple[str, ...]:
        """The open links' names, in the order they were opened."""
        return tuple(self._links)

    def receiver(self, link: str) -> Callable[[bytes, Address | None], None]:
        """What ``link``'s transport calls with each received chunk and its source address;
        calling it is receiving those bytes on that link (benchmarks, tests)."""
        return functools.partial(self._on_chunk, self._links[link])

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks = []
        for link in self._links.values():
            link.transport.close()
        self._links.clear()

    # --- queries --------------------------------------------------------------------------
    def vehicles(self) -> list[VehicleInfo]:
        return [s.info for s in self._states.values() if s.info is not None]

    def health(self) -> list[LinkHealth]:
        return self._health_of(list(self._states.values()))

    def _health_of(self, states: list[VehicleState]) -> list[LinkHealth]:
        t = self.clock.now_s()
        links = self._links
        return [
            s.health(t, links[s.key.link].counters.bad_frames)
            for s in states
            if s.key.link in links
        ]

    def state(self, vehicle: SysId | VehicleKey) -> VehicleState:
        """The vehicle state for a sysid (most recently heard) or an exact key."""
        if isinstance(vehicle, VehicleKey):
            addr = _parse_addr(vehicle.address)
            st = self._states.get((vehicle.link, addr, vehicle.sys_id, vehicle.comp_id))
        else:
            st = self._by_sysid.get(int(vehicle))
        if st is None:
            raise MavlinkError(f"no vehicle {vehicle} heard on any link")
        return st

    # --- receive path ---------------------------------------------------------------------
    def _on_chunk(self, link: _Link, data: bytes, addr: Address | None) -> None:
        t = self.clock.now_s()
        c = self.counters
        c.datagrams += 1
        c.bytes += len(data)
        if self.raw_tap is not None:
            self.raw_tap(link.name, data, t)
        if link.fused:
            # the hot case: one position report from a vehicle already heard, in its own
            # datagram -- straight to its state, without the generic frame objects
            g = wire.global_position(data)
            if g is not None:
                sys_id, comp_id, seq, fields = g
                st = self._states.get((link.name, addr, sys_id, comp_id))
                if st is not None and (self._verify is None or sys_id not in self._keys):
                    c.frames += 1
                    link.counters.frames += 1
                    self._heard(link, addr, st, seq, t)
                    reboots = st.reboots
                    try:
                        st.on_position(fields, t, self.sink)
                    except Exception:  # a handler bug must not kill the link
                        c.handler_errors += 1
                        _log.exception("handler failed on GLOBAL_POSITION_INT")
                    if st.reboots != reboots:
                        self._on_reboot(st)
                    if len(self._lane_values) >= _LANE_HANDOVER:
                        self.flush_positions()  # within a long burst too: latency
                    return
        link.seen[addr] = t
        parser = link.parsers.get(addr) or self._new_parser(link, addr)
        before = link.counters.rejects
        if link.transport.datagram:
            frames = parser.feed_frames(data)
        else:
            frames = parser.frames(data, datagram=False)
        if link.counters.rejects != before:
            self._sync_bad(link)
            _log.debug("bad frame on %s from %s: %s", link.name, addr, link.counters.last_error)
        for f in frames:
            try:
                self._dispatch(link, addr, f, t)
            except Exception:  # a handler bug must not kill the link
                c.handler_errors += 1
                _log.exception("handler failed on %s", wire.msg_name(f.msg_id))
        if not link.transport.datagram:
            self.flush_positions()  # (a UDP link's transport calls it after each burst)

    def flush_positions(self) -> None:
        """Hand the position reports read so far to the sink's lane (see ``__init__``); the
        UDP transports call it after each burst of reads, stream links after each chunk."""
        lane = self._lane
        if lane is not None and lane.values and self._lane_ready is not None:
            try:
                self._lane_ready()
            except Exception:  # a sink bug must not kill the link
                self.counters.handler_errors += 1
                _log.exception("position lane sink failed")

    def _sync_bad(self, link: _Link) -> None:
        c = self.counters
        c.bad_crc = c.garbage = c.unknown_msg = c.truncated = c.bad_signature = 0
        for lk in self._links.values():
            p = lk.counters
            c.bad_crc += p.bad_crc
            c.garbage += p.garbage
            c.unknown_msg += p.unknown_msg
            c.truncated += p.truncated
            c.bad_signature += p.bad_signature

    def _dispatch(self, link: _Link, addr: Address | None, f: wire.Frame, t: float) -> None:
        self.counters.frames += 1
        mid, sys_id, comp_id, seq, m = f
        if self._verify is not None and (cause := self._verify.accept(f)):
            self._unverified(link, cause)
            return
        key = (link.name, addr, sys_id, comp_id)
        st = self._states.get(key)
        if st is None:
            if mid == wire.HEARTBEAT and m.autopilot == 8:
                return  # another GCS or a non-autopilot component: not a vehicle
            st = self._new_state(link, addr, sys_id, comp_id, t)
            if st is None:
                return
        self._heard(link, addr, st, seq, t)
        handler = self._handlers.get(mid)
        reboots = st.reboots
        if handler is not None:
            if mid == wire.HEARTBEAT:
                if m.autopilot == 8:
                    return
                new = handler(st, m, t, self.sink)
                if new:
                    self._senders.discovered(st)
                if st.autopilot is Autopilot.ARDUPILOT and (new or id(st) in self._restream):
                    self._restream.discard(id(st))
                    self._request_streams(st)
            else:
                handler(st, m, t, self.sink)
            if st.reboots != reboots:
                self._on_reboot(st)
        if mid in _PROTOCOL_IDS:
            target = getattr(m, "target_system", 0)
            if target not in (0, self.config.gcs_sys_id):
                self.counters.not_for_us += 1
                return
            box = self._mailbox.get(id(st))
            if box is not None:
                box.put_nowait(m)

    def _heard(
        self, link: _Link, addr: Address | None, st: VehicleState, seq: int, t: float
    ) -> None:
        """A frame from ``st`` at ``addr``: link statistics, and where to reply."""
        st.count_frame(seq, t)
        if addr is not None:
            link.peers[addr] = t

    def _new_state(
        self, link: _Link, addr: Address | None, sys_id: int, comp_id: int, t: float
    ) -> VehicleState | None:
        """The state of a sender heard for the first time, or None when its frames are
        dropped (system id 0, a claim on a system id bound elsewhere: reported)."""
        st = self._senders.new_state(link.name, addr, sys_id, comp_id, t)
        self._sync_senders()
        if st is None and sys_id != 0:
            self._claimed(link, addr, sys_id, t)
        return st

    def _claimed(self, link: _Link, addr: Address | None, sys_id: int, t: float) -> None:
        """Another sender claims ``sys_id``: a SPOOFING_ATTACK hazard for the vehicle bound to
        it, at most once per ``warn_interval_s`` per system id (claims are counted)."""
        last = self._claim_alerts.get(sys_id)
        if last is not None and t - last < self.config.warn_interval_s:
            return
        self._claim_alerts[sys_id] = t
        owner = self._by_sysid.get(sys_id)
        if owner is None:
            return
        where = "" if addr is None else f"{addr[0]}:{addr[1]}"
        message = (
            f"sysid {sys_id} claimed by another sender ({where or 'no address'} on {link.name}); "
            f"it is bound to {owner.key.address or 'no address'} on {owner.key.link}: "
            f"frames dropped ({self.counters.sysid_claims} claims so far)"
        )
        self._ratelog.warning("claim", "%s", message)  # one line per interval for all
        self.sink.on_hazard(owner.hazard(ThreatKind.SPOOFING_ATTACK, t, message))

    def _unverified(self, link: _Link, cause: str) -> None:
        """A frame of a keyed vehicle that failed verification: dropped, counted by cause (a
        wrong signature also in the link's bad frames, as the parser counts them)."""
        v = self._verify
        assert v is not None
        c = self.counters
        c.unsigned, c.replayed = v.counters.unsigned, v.counters.replayed
        if cause == "bad_signature":
            link.counters.bad_signature += 1
            self._sync_bad(link)
        self._ratelog.log(
            logging.DEBUG, f"unverified:{cause}", "dropped on %s: %s", link.name, cause
        )

    def _sync_senders(self) -> None:
        sc = self._senders.counters
        c = self.counters
        c.sysid_zero, c.sysid_claims = sc.sysid_zero, sc.sysid_claims
        c.sysid_collisions = sc.sysid_collisions
        c.vehicles_evicted, c.address_changes = sc.vehicles_evicted, sc.address_changes

    def _busy(self, st: VehicleState) -> bool:
        """A transfer or command exchange with ``st`` is in progress: keep it."""
        lock = self._locks.get(id(st))
        return lock is not None and lock.locked()

    def _forgotten(self, st: VehicleState) -> None:
        """``st`` was evicted: drop what the hub keeps by its id."""
        self._locks.pop(id(st), None)
        self._restream.discard(id(st))

    def _new_parser(self, link: _Link, addr: Address | None) -> wire.Parser:
        """The parser of a source address heard for the first time (room made if full)."""
        if len(link.parsers) >= self.config.max_senders:
            self._trim_senders(link)
        parser = link.parsers[addr] = wire.Parser(link.counters, fast=self.config.fast_decode)
        return parser

    def _trim_senders(self, link: _Link) -> None:
        """``link`` has ``max_senders`` parsers and a new address: forget the oldest eighth."""
        gone = over_cap_keys(link.seen, self.config.max_senders)
        self._forget_addresses(link, gone)

    def _forget_addresses(self, link: _Link, addrs: list[Address | None]) -> None:
        for a in addrs:
            link.seen.pop(a, None)
            if link.parsers.pop(a, None) is not None:
                self.counters.senders_evicted += 1
            if a is not None:
                link.peers.pop(a, None)

    def evict_idle(self) -> None:
        """Forget senders and vehicles not heard for ``sender_idle_s`` (clock time); the
        health loop calls it every ``health_period_s``."""
        t = self.clock.now_s()
        self._senders.evict_idle(t)
        self._sync_senders()
        idle_s = self.config.sender_idle_s
        for link in self._links.values():
            # an address with a vehicle on the fused path is seen through its peers entry
            for a, heard in link.peers.items():
                if link.seen.get(a, -math.inf) < heard:
                    link.seen[a] = heard
            self._forget_addresses(link, idle_keys(link.seen, t, idle_s))
        for sys_id in idle_keys(self._claim_alerts, t, idle_s):
            del self._claim_alerts[sys_id]
        self._ratelog.flush()
        self._report_drops(t)

    def _report_drops(self, t: float) -> None:
        """Once per minute of clock time at most: one line with what senders had dropped or
        forgotten since the last one (a WARNING when a check refused frames)."""
        if t - self._drops_reported[0] < _DROPS_REPORT_S:
            return
        snap = self.counters.snapshot()
        last = self._drops_reported[1]
        moved = {k: snap[k] - last.get(k, 0) for k in _DROP_COUNTERS if snap[k] != last.get(k, 0)}
        self._drops_reported = (t, {k: snap[k] for k in _DROP_COUNTERS})
        if moved:
            level = logging.WARNING if set(moved) & _REFUSALS else logging.INFO
            text = ", ".join(f"{k} {n:,}" for k, n in moved.items())
            _log.log(level, "mavlink senders in the last %.0f s: %s", _DROPS_REPORT_S, text)

    def _on_reboot(self, st: VehicleState) -> None:
        box = self._mailbox.get(id(st))
        if box is not None:
            box.put_nowait(None)  # wake a transfer: it checks st.reboots and fails
        if st.autopilot is Autopilot.ARDUPILOT:
            self._request_streams(st)

    # --- send path ------------------------------------------------------------------------
    def _send(self, link: _Link, frame: bytes, addr: Address | None) -> None:
        link.transport.send(frame, addr)
        if self.raw_tap is not None:
            self.raw_tap(link.name, frame, self.clock.now_s())

    def _encoder(self, st: VehicleState) -> wire.Encoder:
        key = self._keys.get(st.sys_id)
        if key is None:
            enc = self._links[st.key.link].encoder
            assert enc is not None
            return enc
        enc2 = self._signers.get(st.sys_id)
        if enc2 is None:
            enc2 = self._signers[st.sys_id] = wire.Encoder(
                self.config.gcs_sys_id, self.config.gcs_comp_id, key=key
            )
        return enc2

    def _to(self, st: VehicleState, frame: bytes) -> None:
        link = self._links.get(st.key.link)
        if link is None:
            raise _TransferError(f"link {st.key.link} closed")
        self._send(link, frame, self._addr.get(id(st)))

    def _request_streams(self, st: VehicleState) -> None:
        """ArduPilot sends no telemetry until asked: REQUEST_DATA_STREAM (old) and
        SET_MESSAGE_INTERVAL (new) for the messages we use."""
        enc = self._encoder(st)
        ts, tc = st.sys_id, st.key.comp_id
        hz = self.config.ardupilot_stream_hz
        self._to(st, enc.request_data_stream(ts, tc, MAV_DATA_STREAM_ALL, max(1, round(hz))))
        for mid in _ARDUPILOT_STREAM_MSGS:
            params = (float(mid), 1e6 / hz, 0.0, 0.0, 0.0, 0.0, 0.0)
            self._to(st, enc.command_long(ts, tc, MAV_CMD_SET_MESSAGE_INTERVAL, 0, params))

    def _heartbeats_for(self, link: _Link, addr: Address | None, *, any_addr: bool) -> list[bytes]:
        """The GCS heartbeats for one peer: signed with the key of each keyed vehicle heard
        there (a vehicle enforcing signing drops unsigned ones and would see its GCS as lost),
        plus an unsigned one if an unkeyed vehicle is there or none was heard yet."""
        enc = link.encoder
        assert enc is not None
        if not self._keys:
            return [enc.heartbeat()]
        signed: dict[int, bytes] = {}
        unsigned = False
        for (name, a, sys_id, _comp), st in list(self._states.items()):
            if name != link.name or (a != addr and not any_addr):
                continue
            if sys_id in self._keys:
                if sys_id not in signed:
                    signed[sys_id] = self._encoder(st).heartbeat()
            else:
                unsigned = True
        out = list(signed.values())
        if unsigned or not out:
            out.append(enc.heartbeat())
        return out

    async def _heartbeat_loop(self) -> None:
        while True:
            for link in list(self._links.values()):
                if link.transport.endpoint.kind.value == "udpin":
                    for peer in list(link.peers):
                        for frame in self._heartbeats_for(link, peer, any_addr=False):
                            self._send(link, frame, peer)
                else:
                    for frame in self._heartbeats_for(link, None, any_addr=True):
                        self._send(link, frame, None)
            await asyncio.sleep(self.config.heartbeat_period_s)

    async def _health_loop(self) -> None:
        chunk = 50  # vehicles per loop turn (~0.5 ms here): a large fleet must not stall reading
        while True:
            await asyncio.sleep(self.config.health_period_s)
            self.evict_idle()
            self.counters.dropped_link_down = sum(
                lk.transport.dropped_down for lk in self._links.values()
            )
            states = list(self._states.values())
            for i in range(0, len(states), chunk):
                for h in self._health_of(states[i : i + chunk]):
                    self.sink.on_link_health(h)
                if i + chunk < len(states):
                    await asyncio.sleep(0)

    # --- protocol exchanges -----------------------------------------------------------------
    def _budget_s(self, deadline_t_s: float | None) -> float:
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
    async def _exchange(self, st: VehicleState) -> AsyncIterator[asyncio.Queue[wire.MavMsg]]:
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
    ) -> UploadResult:
        """Upload ``plan`` as a mission, read it back, set the current item and mission mode.
        ``start_index`` is the plan waypoint flown first (flagged current); the vertical speeds
        let a climb on the spot keep the plan's time (see :func:`plan_to_mission_items`).
        Never raises for vehicle behaviour: failures are in the result."""
        t0 = time.monotonic()
        try:
            st = self.state(sys_id)
        except MavlinkError as exc:
            return UploadResult(
                ok=False, verified=False, attempts=0, items=0, duration_s=0.0, error=str(exc)
            )
        ap = autopilot or st.autopilot
        items = plan_to_mission_items(
            plan,
            ap,
            home,
            start_index=start_index,
            max_speed_mps=self.config.max_speed_mps,
            climb_rate_mps=climb_rate_mps,
            descent_rate_mps=descent_rate_mps,
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
        """Upload raw mission items (see :meth:`upload_plan`)."""
        t0 = time.monotonic() if _t0 is None else _t0
        attempts = 0
        try:
            st = self.state(vehicle)
            end = t0 + self._budget_s(deadline_t_s)
            async with self._exchange(st) as box:
                reboots = st.reboots
                attempts = await self._upload(st, box, items, end, reboots)
                got = await self._download(st, box, end, reboots)
                for sent, back in zip(items, got, strict=False):
                    if sent.seq == 0 and st.autopilot is Autopilot.ARDUPILOT:
                        continue  # ArduPilot reports its own home at seq 0, not what we sent
                    diff = same_item(sent, back)
                    if diff:
                        raise _TransferError(f"readback item {sent.seq} differs: {diff}")
                if len(got) != len(items):
                    raise _TransferError(f"readback has {len(got)} items, sent {len(items)}")
                cur = current_seq(items)
                current_set = await self._set_current(st, box, cur, end, reboots)
            mode_set = True
            if set_mission_mode and st.mode is not FlightMode.MISSION:
                res = await self.send_mode(st.key, FlightMode.MISSION, deadline_t_s=deadline_t_s)
                mode_set = res.ok
        except _TransferError as exc:
            self.counters.uploads_failed += 1
            _log.warning("upload to %s failed: %s", vehicle, exc)
            return UploadResult(
                ok=False,
                verified=False,
                attempts=attempts,
                items=len(items),
                duration_s=time.monotonic() - t0,
                error=str(exc),
            )
        except MavlinkError as exc:
            return UploadResult(
                ok=False,
                verified=False,
                attempts=attempts,
                items=len(items),
                duration_s=time.monotonic() - t0,
                error=str(exc),
            )
        self.counters.uploads_verified += 1
        err = (
            ""
            if current_set and mode_set
            else ("current item not confirmed" if not current_set else "mission mode not confirmed")
        )
        return UploadResult(
            ok=True,
            verified=True,
            attempts=attempts,
            items=len(items),
            duration_s=time.monotonic() - t0,
            error=err,
            current_set=current_set,
            mode_set=mode_set,
        )

    def _check(self, st: VehicleState, reboots: int, end: float) -> None:
        if st.reboots != reboots:
            raise _TransferError("vehicle rebooted during the transfer")
        if time.monotonic() >= end:
            raise _TransferError("deadline passed")

    def _cancel(self, st: VehicleState) -> None:
        with contextlib.suppress(_TransferError):
            self._to(
                st,
                self._encoder(st).mission_ack(
                    st.sys_id, st.key.comp_id, MAV_MISSION_OPERATION_CANCELLED
                ),
            )

    async def _upload(
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
        enc = self._encoder(st)
        ts, tc = st.sys_id, st.key.comp_id
        n = len(items)
        step = _Step(self.config)
        attempts = 1
        self._to(st, enc.mission_count(ts, tc, n))
        sent_t = time.monotonic()
        highest = -1  # highest item the vehicle has requested
        sent_hi = -1  # highest item we have sent (asked for or sent ahead)
        last_sent = False  # item n-1 went out
        silent = 0
        try:
            while True:
                self._check(st, reboots, end)
                m = await self._get(box, min(sent_t + step.rto, end) - time.monotonic())
                self._check(st, reboots, end)
                if m is None:
                    silent += 1
                    if silent > self.config.max_retries:
                        if last_sent:
                            # the vehicle may have taken the last item and its ACK be lost (and
                            # not every vehicle repeats it): the readback decides
                            _log.debug("%s: no ACK of the last item; verifying", st.key)
                            return attempts
                        raise _TransferError(
                            f"no answer after {silent - 1} retries (last item requested "
                            f"{highest if highest >= 0 else None})"
                        )
                    step.backoff()
                    attempts += 1
                    self.counters.mission_retries += 1
                    if highest < 0:
                        self._to(st, enc.mission_count(ts, tc, n))
                    else:
                        # the vehicle expects one of highest .. sent_hi + 1
                        top = min(n - 1, sent_hi + 1, highest + _UPLOAD_WINDOW - 1)
                        for _ in range(2):  # twice, as the retries of _download
                            for seq in range(highest, top + 1):
                                self._to(st, enc.mission_item_int(ts, tc, items[seq]))
                        sent_hi = max(sent_hi, top)
                        last_sent = sent_hi == n - 1
                    sent_t = time.monotonic()
                    continue
                mid = m._header.msgId
                if mid in (wire.MISSION_REQUEST_INT, wire.MISSION_REQUEST):
                    if getattr(m, "mission_type", 0) != 0:
                        continue
                    seq = int(m.seq)
                    if not 0 <= seq < n:
                        _log.debug("vehicle asked for item %d of %d", seq, n)
                        continue
                    if seq < highest:
                        continue  # overtaken by a later request (reordered or re-requested)
                    if seq > highest:
                        step.progress(time.monotonic() - sent_t)
                        highest = seq
                        silent = 0
                    self._to(st, enc.mission_item_int(ts, tc, items[seq]))
                    sent_hi = max(sent_hi, seq)
                    last_sent = sent_hi == n - 1
                    sent_t = time.monotonic()
                elif mid == wire.MISSION_ACK:
                    if getattr(m, "mission_type", 0) != 0:
                        continue
                    if m.type == MAV_MISSION_ACCEPTED:
                        if last_sent:
                            return attempts
                        continue  # a stale ACK of an earlier transfer
                    if m.type == MAV_MISSION_INVALID_SEQUENCE:
                        continue  # ArduPilot's answer to an item it did not ask for
                    if m.type == MAV_MISSION_ERROR and last_sent:
                        # ArduPilot answers a repeated last item with ERROR once the upload
                        # is complete (its ACCEPTED was lost): the readback decides
                        _log.debug("%s: ERROR after the last item; verifying by readback", st.key)
                        return attempts
                    raise _TransferError(f"vehicle rejected the mission: {_mission_result(m.type)}")
        except _TransferError:
            self._cancel(st)
            raise

    async def download_mission(
        self, sys_id: SysId | VehicleKey, *, deadline_t_s: float | None = None
    ) -> list[MissionItem]:
        """The vehicle's mission (MISSION_REQUEST_LIST). Raises :class:`MavlinkError`."""
        st = self.state(sys_id)
        end = time.monotonic() + self._budget_s(deadline_t_s)
        async with self._exchange(st) as box:
            try:
                return await self._download(st, box, end, st.reboots)
            except _TransferError as exc:
                raise MavlinkError(f"download from {sys_id} failed: {exc}") from exc

    async def _download(
        self, st: VehicleState, box: asyncio.Queue[wire.MavMsg], end: float, reboots: int
    ) -> list[MissionItem]:
        enc = self._encoder(st)
        ts, tc = st.sys_id, st.key.comp_id
        step = _Step(self.config)
        # drain protocol leftovers of the upload (late re-requests, duplicate ACKs)
        while not box.empty():
            box.get_nowait()
        count: int | None = None
        got: list[MissionItem] = []
        silent = 0
        refusals = 0

        def request() -> bytes:
            if count is None:
                return enc.mission_request_list(ts, tc)
            return enc.mission_request_int(ts, tc, len(got))

        self._to(st, request())
        sent_t = time.monotonic()
        try:
            while True:
                self._check(st, reboots, end)
                m = await self._get(box, min(sent_t + step.rto, end) - time.monotonic())
                self._check(st, reboots, end)
                if m is None:
                    silent += 1
                    if silent > self.config.max_retries:
                        raise _TransferError(f"no answer to download after {silent - 1} retries")
                    step.backoff()
                    self.counters.mission_retries += 1
                    # a retry goes out twice: a lost request or a lost answer costs a whole
                    # timeout, a duplicate costs one datagram (PX4 answers a repeated request
                    # for the item it just sent, ArduPilot answers any request)
                    self._to(st, request())
                    self._to(st, request())  # encoded anew: a signed frame is never replayed
                    sent_t = time.monotonic()
                    continue
                mid = m._header.msgId
                if getattr(m, "mission_type", 0) != 0:
                    continue
                if mid == wire.MISSION_COUNT and count is None:
                    count = int(m.count)
                elif mid == wire.MISSION_ITEM_INT and count is not None and m.seq == len(got):
                    got.append(_item_from(m))
                elif mid == wire.MISSION_ACK and m.type != MAV_MISSION_ACCEPTED:
                    # a late answer to an upload item repeated after the upload ended, or the
                    # vehicle dropped the transfer (PX4 does on a request it did not expect):
                    # start over; a vehicle that keeps refusing fails the download
                    refusals += 1
                    if refusals > _DOWNLOAD_RESTARTS:
                        raise _TransferError(
                            f"vehicle refused the download: {_mission_result(m.type)}"
                        )
                    count = None
                    got.clear()
                    self._to(st, request())
                    sent_t = time.monotonic()
                    continue
                else:
                    continue
                step.progress(time.monotonic() - sent_t)
                silent = 0
                if count is not None and len(got) >= count:
                    self._to(st, enc.mission_ack(ts, tc, MAV_MISSION_ACCEPTED))
                    return got
                self._to(st, request())
                sent_t = time.monotonic()
        except _TransferError:
            self._cancel(st)
            raise

    async def _set_current(
        self,
        st: VehicleState,
        box: asyncio.Queue[wire.MavMsg],
        seq: int,
        end: float,
        reboots: int,
    ) -> bool:
        """MISSION_SET_CURRENT until MISSION_CURRENT reports ``seq``; resent on the same
        adaptive timeout as mission items (not the 0.5 s command timeout: on a lossy link
        that one wait would cost more than the whole transfer)."""
        enc = self._encoder(st)
        step = _Step(self.config)
        for attempt in range(self.config.max_retries + 1):
            for _ in range(1 if attempt == 0 else 2):  # retries twice, as in _download
                self._to(st, enc.mission_set_current(st.sys_id, st.key.comp_id, seq))
            wait_end = min(end, time.monotonic() + step.rto)
            while (left := wait_end - time.monotonic()) > 0:
                self._check(st, reboots, end)
                m = await self._get(box, left)
                if m is not None and m._header.msgId == wire.MISSION_CURRENT and m.seq == seq:
                    return True
            self._check(st, reboots, end)
            step.backoff()
        return False

    # --- commands -------------------------------------------------------------------------
    async def send_command(
        self,
        sys_id: SysId | VehicleKey,
        command: Command,
        *,
        deadline_t_s: float | None = None,
    ) -> CommandResult:
        """HOLD / RESUME / RTL / LAND / GOTO mapped to the vehicle's autopilot."""
        try:
            st = self.state(sys_id)
        except MavlinkError as exc:
            return CommandResult(ok=False, result=None, attempts=0, error=str(exc))
        kind = command.kind
        mode = {
            CommandKind.HOLD: FlightMode.HOLD,
            CommandKind.RESUME: FlightMode.MISSION,
            CommandKind.RTL: FlightMode.RTL,
        }.get(kind)
        if mode is not None:
            return await self.send_mode(st.key, mode, deadline_t_s=deadline_t_s)
        if kind is CommandKind.LAND:
            if st.autopilot is Autopilot.ARDUPILOT and st.kind is VehicleKind.FIXED_WING:
                params = (0.0,) * 7
                return await self._command_long(st, MAV_CMD_DO_LAND_START, params, deadline_t_s)
            if st.autopilot is Autopilot.ARDUPILOT:
                return await self.send_mode(st.key, FlightMode.LAND, deadline_t_s=deadline_t_s)
            params = (0.0, 0.0, 0.0, _NAN, _NAN, _NAN, _NAN)
            return await self._command_long(st, MAV_CMD_NAV_LAND, params, deadline_t_s)
        target = command.target
        if target is None:
            return CommandResult(ok=False, result=None, attempts=0, error="GOTO needs a target")
        return await self._command_int(st, MAV_CMD_DO_REPOSITION, target, deadline_t_s)

    async def send_mode(
        self, sys_id: SysId | VehicleKey, mode: FlightMode, *, deadline_t_s: float | None = None
    ) -> CommandResult:
        st = self.state(sys_id)
        p = set_mode_params(st.autopilot, st.kind, mode)
        if p is None:
            return CommandResult(
                ok=False,
                result=None,
                attempts=0,
                error=f"{st.autopilot.value} has no mode {mode.value}",
            )
        params = (p[0], p[1], p[2], 0.0, 0.0, 0.0, 0.0)
        return await self._command_long(st, MAV_CMD_DO_SET_MODE, params, deadline_t_s)

    async def _command_long(
        self,
        st: VehicleState,
        cmd: int,
        params: tuple[float, float, float, float, float, float, float],
        deadline_t_s: float | None,
    ) -> CommandResult:
        enc = self._encoder(st)
        return await self._command(
            st,
            cmd,
            lambda conf: enc.command_long(st.sys_id, st.key.comp_id, cmd, conf, params),
            deadline_t_s,
        )

    async def _command_int(
        self, st: VehicleState, cmd: int, target: Position, deadline_t_s: float | None
    ) -> CommandResult:
        enc = self._encoder(st)
        # DO_REPOSITION: speed -1 (default), flag CHANGE_MODE (switch to guided/hold), yaw NaN
        frame = enc.command_int(
            st.sys_id,
            st.key.comp_id,
            MAV_FRAME_GLOBAL,
            cmd,
            (-1.0, 1.0, 0.0, _NAN),
            round(target.lat_deg * 1e7),
            round(target.lon_deg * 1e7),
            target.alt_amsl_m,
        )
        return await self._command(st, cmd, lambda _conf: frame, deadline_t_s)

    async def _command(
        self,
        st: VehicleState,
        cmd: int,
        build: Callable[[int], bytes],
        deadline_t_s: float | None,
    ) -> CommandResult:
        end = time.monotonic() + self._budget_s(deadline_t_s)
        attempts = 0
        result: int | None = None
        async with self._exchange(st) as box:
            reboots = st.reboots
            try:
                for conf in range(self.config.command_retries + 1):
                    if time.monotonic() >= end:
                        break
                    attempts += 1
                    self._to(st, build(min(conf, 255)))
                    wait_end = min(end, time.monotonic() + self.config.command_timeout_s)
                    while (left := wait_end - time.monotonic()) > 0:
                        self._check(st, reboots, end + 1.0)
                        m = await self._get(box, left)
                        if m is None or m._header.msgId != wire.COMMAND_ACK or m.command != cmd:
                            continue
                        result = int(m.result)
                        if result == MAV_RESULT_IN_PROGRESS:
                            wait_end = min(end, time.monotonic() + self.config.command_timeout_s)
                            continue
                        ok = result == MAV_RESULT_ACCEPTED
                        return CommandResult(
                            ok=ok,
                            result=result,
                            attempts=attempts,
                            error="" if ok else _command_result(result),
                        )
            except _TransferError as exc:
                return CommandResult(ok=False, result=result, attempts=attempts, error=str(exc))
        return CommandResult(
            ok=False,
            result=result,
            attempts=attempts,
            error=f"no COMMAND_ACK after {attempts} attempts",
        )


def _parse_addr(text: str) -> Address | None:
    if not text:
        return None
    host, _, port = text.rpartition(":")
    try:
        return (host, int(port))
    except ValueError:
        return (host, 0)


def _item_from(m: wire.MavMsg) -> MissionItem:
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


def _mission_result(code: int) -> str:
    return f"MAV_MISSION_{_MISSION_RESULTS.get(code, str(code))}"


def _command_result(code: int) -> str:
    return f"MAV_RESULT_{_COMMAND_RESULTS.get(code, str(code))}"
