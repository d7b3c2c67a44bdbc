"""MavlinkHub: links, vehicle discovery, telemetry routing, mission upload/download, commands.

Threading model: everything runs on the asyncio loop; receive callbacks parse and dispatch
synchronously (no per-frame task), protocol exchanges (upload, download, commands) are
coroutines that wait on a per-vehicle mailbox with timeouts. The hub is the link/dispatch
core and holds the parts that run the exchanges, each passed what it needs and none importing
the hub: :attr:`MavlinkHub.transfers` (:class:`~adapters.mavlink.transfer.Transfers`: mission
protocol, commands, the mailboxes; it reaches the hub through the small
:class:`~adapters.mavlink.transfer.VehicleLink` protocol), :attr:`MavlinkHub.uploads`
(:class:`~adapters.mavlink.upload.Uploads`: upload, readback, current item, mission mode) and
:attr:`MavlinkHub.commands` (:class:`~adapters.mavlink.commands.Commands`: per-autopilot
command mapping); the hub's mission and command methods hand over to them. A bad frame
is counted in :attr:`MavlinkHub.counters` and logged at debug level; nothing from the wire
raises into the loop.

Identity: a vehicle is (link, source address, sysid, compid) = :class:`VehicleKey`; API calls
take a ``SysId`` (resolved to its most recently heard component) or a ``VehicleKey``. Replies
are unicast to the address the vehicle was last heard from. A system id is bound to the link
and address it was first heard on; another sender claiming it is dropped, counted and reported
as a SYSID_CONFLICT hazard (an operator warning: the bound vehicle flies on) instead of taking
it over; system id 0 is never a vehicle; with a key in ``signing_keys`` a vehicle's frames must
be signed with it (see :mod:`adapters.mavlink.senders`, :mod:`adapters.mavlink.signing`).
Per-sender state is capped and forgotten when idle (``max_senders``, ``max_vehicles``,
``sender_idle_s``).

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
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from adapters.mavlink import wire
from adapters.mavlink.adsb_relay import AdsbRelay, MessageHandler
from adapters.mavlink.commands import Commands
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.endpoint import parse_endpoint
from adapters.mavlink.handlers import message_handlers
from adapters.mavlink.hub_report import HubCounters, LinkState
from adapters.mavlink.mission import MissionItem
from adapters.mavlink.modes import MAV_AUTOPILOT_INVALID
from adapters.mavlink.senders import Senders, idle_keys, over_cap_keys
from adapters.mavlink.signing import SignatureCheck
from adapters.mavlink.transfer import (
    CommandResult,
    MavlinkError,
    Params7,
    TransferError,
    Transfers,
    UploadResult,
)
from adapters.mavlink.transport import Address, Backoff, Transport
from adapters.mavlink.upload import Uploads
from adapters.mavlink.vehicle import VehicleInfo, VehicleState
from adapters.remoteid.vehicles import RidVehicles
from gcs_utm.clock import Clock
from gcs_utm.messages import FlightMode, HazardReport, LinkHealth, VehicleKey, VehicleStatus
from gcs_utm.model import (
    LANE_STRIDE,
    Autopilot,
    Command,
    FlightPlan,
    Measurement,
    Position,
    PositionLane,
    SysId,
    ThreatKind,
)
from gcs_utm.ratelog import RateLimitedLog

_log = logging.getLogger(__name__)

RawTap = Callable[[str, bytes, float], None]

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_DATA_STREAM_ALL = 0
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
numbers (16 reports) wait: tracking should not wait for the end of a long burst of reads (see
MavlinkHub.flush_positions)."""


_DROPS_REPORT_S = 60.0  # a summary of refused and forgotten senders at most this often
_REFUSALS = frozenset(
    {"bad_signature", "unsigned", "replayed", "sysid_zero", "sysid_claims", "address_changes"}
)
_DROP_COUNTERS = (*sorted(_REFUSALS), "senders_evicted", "vehicles_evicted", "links_down")


class TelemetrySink(Protocol):
    def on_measurement(self, m: Measurement) -> None: ...
    def on_status(self, s: VehicleStatus) -> None: ...
    def on_hazard(self, h: HazardReport) -> None: ...
    def on_vehicle(self, v: VehicleInfo) -> None: ...
    def on_link_health(self, h: LinkHealth) -> None: ...


@dataclass(slots=True)
class _Link:
    name: str
    transport: Transport
    parsers: dict[Address | None, wire.Parser] = field(default_factory=dict)
    counters: wire.ParseCounters = field(default_factory=wire.ParseCounters)
    encoder: wire.Encoder | None = None
    peers: dict[Address, float] = field(default_factory=dict)  # vehicles' addresses
    seen: dict[Address | None, float] = field(default_factory=dict)  # any sender's last chunk
    datagram: bool = False  # UDP: each chunk a datagram, parsed on its own


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
        self.counters: HubCounters = HubCounters()
        # A sink that takes positions in columns (the USM: ``position_lane`` and
        # ``on_position_lane``) gets GLOBAL_POSITION_INT as entries of its lane, handed over
        # after each read (a UDP burst, a stream chunk); other sinks get each entry as its
        # Measurement at once (VehicleState.on_global_position).
        self._lane: PositionLane | None = getattr(sink, "position_lane", None)
        self._lane_ready: Callable[[], None] | None = getattr(sink, "on_position_lane", None)
        if self._lane is None or self._lane_ready is None:
            self._lane = self._lane_ready = None
        self._lane_values: list[float] = self._lane.values if self._lane is not None else []
        self._links: dict[str, _Link] = {}
        # the exchanges (the hub is their VehicleLink: vehicle table and send path)
        self.transfers = Transfers(self, config, clock, self.counters)
        self.uploads = Uploads(self.transfers)
        self.commands = Commands(self.transfers, self.uploads)
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
        self.adsb_relay = AdsbRelay()  # ADSB_VEHICLE relayed by a vehicle -> ADS-B measurement
        self.remote_id = RidVehicles()  # OPEN_DRONE_ID_* and ODID texts (docs/remote-id.md)
        self._handlers = message_handlers(self.adsb_relay, self.remote_id)
        # messages no handler reads are framed, not decoded (a signed link decodes them all)
        read = {*self._handlers, *_PROTOCOL_IDS}
        self._unread = frozenset() if self._keys else wire.unread_ids(read)

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
        link = _Link(name=name, transport=transport, datagram=transport.datagram)
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
            self.transfers.wake(st)  # its frames cannot go out
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

    def add_replay_link(self, name: str) -> Callable[[bytes, Address | None], None]:
        """A receive-only datagram link that its caller feeds (``gcs-utm replay``: each call
        one recorded packet, at the clock's time); frames sent on it go nowhere."""
        transport = Transport(parse_endpoint("udpin:127.0.0.1:0"))  # never opened
        self._links[name] = _Link(name=name, transport=transport, datagram=True)
        self._links[name].encoder = wire.Encoder(self.config.gcs_sys_id, self.config.gcs_comp_id)
        return self.receiver(name)

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
    def states(self) -> list[VehicleState]:
        """Every sender heard (vehicles, and components that are none), as first heard."""
        return list(self._states.values())

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

    # --- missions and commands (the parts: see the module docstring) -----------------------
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
        """Upload ``plan`` as a mission, verified, started (:meth:`Uploads.upload_plan`)."""
        return await self.uploads.upload_plan(
            sys_id,
            plan,
            autopilot=autopilot,
            start_index=start_index,
            home=home,
            deadline_t_s=deadline_t_s,
            set_mission_mode=set_mission_mode,
            climb_rate_mps=climb_rate_mps,
            descent_rate_mps=descent_rate_mps,
            min_speed_mps=min_speed_mps,
            lands=lands,
        )

    async def upload_items(
        self,
        vehicle: SysId | VehicleKey,
        items: list[MissionItem],
        *,
        deadline_t_s: float | None = None,
        set_mission_mode: bool = True,
    ) -> UploadResult:
        """Upload raw mission items (:meth:`Uploads.upload_items`)."""
        return await self.uploads.upload_items(
            vehicle, items, deadline_t_s=deadline_t_s, set_mission_mode=set_mission_mode
        )

    async def download_mission(
        self, sys_id: SysId | VehicleKey, *, deadline_t_s: float | None = None
    ) -> list[MissionItem]:
        """The vehicle's mission (:meth:`Transfers.download_mission`)."""
        return await self.transfers.download_mission(sys_id, deadline_t_s=deadline_t_s)

    async def send_command(
        self, sys_id: SysId | VehicleKey, command: Command, *, deadline_t_s: float | None = None
    ) -> CommandResult:
        """HOLD / RESUME / RTL / LAND / GOTO for the vehicle's autopilot (:class:`Commands`)."""
        return await self.commands.send_command(sys_id, command, deadline_t_s=deadline_t_s)

    async def send_mode(
        self, sys_id: SysId | VehicleKey, mode: FlightMode, *, deadline_t_s: float | None = None
    ) -> CommandResult:
        """DO_SET_MODE to ``mode`` until its COMMAND_ACK."""
        return await self.transfers.send_mode(sys_id, mode, deadline_t_s=deadline_t_s)

    async def command_long(
        self,
        vehicle: SysId | VehicleKey,
        cmd: int,
        params: Params7,
        *,
        deadline_t_s: float | None = None,
    ) -> CommandResult:
        """One COMMAND_LONG until its COMMAND_ACK (arming, take-off, any MAV_CMD)."""
        return await self.transfers.command_long(vehicle, cmd, params, deadline_t_s=deadline_t_s)

    async def wait_mode(self, st: VehicleState, mode: FlightMode, timeout_s: float) -> bool:
        """True once the vehicle's HEARTBEAT shows ``mode`` (within ``timeout_s`` real s)."""
        return await self.transfers.wait_mode(st, mode, timeout_s)

    # --- receive path ---------------------------------------------------------------------
    def _on_chunk(self, link: _Link, data: bytes, addr: Address | None) -> None:
        t = self.clock.now_s()
        c = self.counters
        c.datagrams += 1
        c.bytes += len(data)
        if self.raw_tap is not None:
            self.raw_tap(link.name, data, t)
        link.seen[addr] = t
        parser = link.parsers.get(addr) or self._new_parser(link, addr)
        before = link.counters.rejects
        # one datagram: the fast decoder (pymavlink for the rest); a stream chunk: pymavlink
        frames = parser.feed_frames(data) if link.datagram else parser.frames(data, datagram=False)
        if link.counters.rejects != before:
            self._sync_bad(link)
            _log.debug("bad frame on %s from %s: %s", link.name, addr, link.counters.last_error)
        for f in frames:
            try:
                self._dispatch(link, addr, f, t)
            except Exception:  # a handler bug must not kill the link
                c.handler_errors += 1
                _log.exception("handler failed on %s", wire.msg_name(f.msg_id))
        if not link.datagram or len(self._lane_values) >= _LANE_HANDOVER:
            # a UDP link's transport calls it after each burst, and within a long one here
            self.flush_positions()

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
        st = self._states.get((link.name, addr, sys_id, comp_id))
        if st is None:
            if mid == wire.HEARTBEAT and m.autopilot == MAV_AUTOPILOT_INVALID:
                self.counters.gcs_heartbeats += 1
                return  # another GCS or a non-autopilot component: not a vehicle
            st = self._new_state(link, addr, sys_id, comp_id, t)
            if st is None:
                return
        st.count_frame(seq, t)  # link statistics
        if addr is not None:
            link.peers[addr] = t  # where to reply
        handler = self._handlers.get(mid)
        if handler is not None:
            reboots = st.reboots
            if mid == wire.HEARTBEAT:
                self._on_heartbeat(st, handler, m, t)
            else:
                handler(st, m, t, self.sink)
            if st.reboots != reboots:
                self._on_reboot(st)
        if mid in _PROTOCOL_IDS:
            self._to_mailbox(st, m)

    def _on_heartbeat(
        self, st: VehicleState, handler: MessageHandler, m: wire.MavMsg, t: float
    ) -> None:
        """A vehicle's HEARTBEAT: discovery, and ArduPilot's streams asked for when it is new
        or its link came back."""
        if m.autopilot == MAV_AUTOPILOT_INVALID:
            self.counters.gcs_heartbeats += 1
            return  # a component without an autopilot sharing the vehicle's ids
        new = handler(st, m, t, self.sink)
        if new:
            self._senders.discovered(st)
        if st.autopilot is Autopilot.ARDUPILOT and (
            new or id(st) in self._restream or _streams_unanswered(st, t)
        ):
            self._restream.discard(id(st))
            self._request_streams(st)

    def _to_mailbox(self, st: VehicleState, m: wire.MavMsg) -> None:
        """A protocol message (mission, command ack) to the transfer waiting on ``st``, when
        it is addressed to us or to everybody."""
        target = getattr(m, "target_system", 0)
        if target not in (0, self.config.gcs_sys_id):
            self.counters.not_for_us += 1
            return
        self.transfers.deliver(st, m)

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
        """Another sender claims ``sys_id``: a SYSID_CONFLICT hazard for the vehicle bound to
        it, at most once per ``warn_interval_s`` per system id (claims are counted). Not
        SPOOFING_ATTACK: that is the vehicle's own GNSS being spoofed, and EM suspends the
        vehicle for it; here the impostor's frames never reach the vehicle's state."""
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
        self.sink.on_hazard(owner.hazard(ThreatKind.SYSID_CONFLICT, t, message))

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
        return self.transfers.busy(st)

    def _forgotten(self, st: VehicleState) -> None:
        """``st`` was evicted: drop what the hub keeps by its id."""
        self.transfers.forget(st)
        self._restream.discard(id(st))

    def _new_parser(self, link: _Link, addr: Address | None) -> wire.Parser:
        """The parser of a source address heard for the first time (room made if full)."""
        if len(link.parsers) >= self.config.max_senders:
            self._trim_senders(link)
        parser = link.parsers[addr] = wire.Parser(
            link.counters, fast=self.config.fast_decode, skip=self._unread
        )
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
        self.transfers.wake(st)  # a transfer checks st.reboots and fails
        if st.autopilot is Autopilot.ARDUPILOT:
            self._request_streams(st)

    # --- send path ------------------------------------------------------------------------
    def _send(self, link: _Link, frame: bytes, addr: Address | None) -> None:
        link.transport.send(frame, addr)
        if self.raw_tap is not None:
            self.raw_tap(link.name, frame, self.clock.now_s())

    def encoder(self, st: VehicleState) -> wire.Encoder:
        """The encoder for frames to ``st``: signed with its key, if it has one."""
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

    def send_to(self, st: VehicleState, frame: bytes) -> None:
        """``frame`` to where ``st`` was last heard (TransferError: its link is closed)."""
        link = self._links.get(st.key.link)
        if link is None:
            raise TransferError(f"link {st.key.link} closed")
        self._send(link, frame, self._addr.get(id(st)))

    def send_raw(self, vehicle: SysId | VehicleKey, name: str, *args: object) -> None:
        """Send message ``name`` (its pymavlink encoder name) from us to ``vehicle``."""
        st = self.state(vehicle)
        self.send_to(st, self.encoder(st).raw(name, *args))

    def _request_streams(self, st: VehicleState) -> None:
        """ArduPilot sends no telemetry until asked: REQUEST_DATA_STREAM (old) and
        SET_MESSAGE_INTERVAL (new) for the messages we use."""
        enc = self.encoder(st)
        ts, tc = st.sys_id, st.key.comp_id
        hz = self.config.ardupilot_stream_hz
        st.streams_asked_t_s = self.clock.now_s()
        self.send_to(st, enc.request_data_stream(ts, tc, MAV_DATA_STREAM_ALL, max(1, round(hz))))
        for mid in _ARDUPILOT_STREAM_MSGS:
            params = (float(mid), 1e6 / hz, 0.0, 0.0, 0.0, 0.0, 0.0)
            self.send_to(st, enc.command_long(ts, tc, MAV_CMD_SET_MESSAGE_INTERVAL, 0, params))

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
                    signed[sys_id] = self.encoder(st).heartbeat()
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
        chunk = 50  # vehicles per loop turn: a large fleet must not stall reading
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


def _parse_addr(text: str) -> Address | None:
    if not text:
        return None
    host, _, port = text.rpartition(":")
    try:
        return (host, int(port))
    except ValueError:
        return (host, 0)


STREAM_RETRY_S = 5.0
"""Seconds after asking an ArduPilot for its streams without a position back before asking
again."""


def _streams_unanswered(st: VehicleState, t_s: float) -> bool:
    """An ArduPilot that heartbeats but sent no position in the ``STREAM_RETRY_S`` since its
    streams were last asked for: the request was lost or undone (SITL reloads its parameter
    defaults, the stream rates among them, while it boots), so it is asked again. Positions
    from before the request do not count: a vehicle restarted after sending some (its link
    back, a reboot) was otherwise never asked again and stayed silent but for heartbeats."""
    asked = st.streams_asked_t_s
    if asked is None or t_s - asked < STREAM_RETRY_S:
        return False
    return st.position_t_s is None or st.position_t_s <= asked  # none after the request
