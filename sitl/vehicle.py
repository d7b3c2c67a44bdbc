"""One simulated vehicle: MAVLink links, telemetry streams, commands, flight modes, faults.

The vehicle is driven by `advance(t_s)` (simulated seconds since fleet start) from the fleet
ticker, which integrates the kinematics in fixed steps of at most PHYSICS_DT_S, runs the mode
logic and sends due streams. Sockets feed `_receive`; nothing here blocks and nothing a peer
sends can raise out of a handler (bad input is counted in `counters`).

Truth vs. report: `lat_deg`/`lon_deg`/`alt_amsl_m` are the true position; telemetry reports the
true position plus the spoofing offset, the jamming drift and the configured GNSS noise.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

from sitl import mission as mp
from sitl._mav import Encoder, Inbound, Parser, const, msg_id_of, name_of
from sitl.physics import Goal, KinState, LocalTangent, step_fixed_wing, step_multirotor
from sitl.spec import (
    ARDUPILOT,
    DEFAULT_FAULT_VALUE,
    FIXED_WING,
    FaultKind,
    FaultSpec,
    MissionItemSpec,
    SimTime,
    VehicleSpec,
)

_log = logging.getLogger(__name__)

PHYSICS_DT_S = 0.05  # 20 Hz of simulated time
HISTORY_PERIOD_S = 1.0  # position_history sampling, simulated s
DISARM_AFTER_LAND_S = 2.0  # PX4 COM_DISARM_LAND
DISARM_PREFLIGHT_S = 10.0  # PX4 COM_DISARM_PRFLT: armed on the ground without take-off
BAT_LOW_PCT, BAT_CRIT_PCT, BAT_EMERG_PCT = 15.0, 7.0, 3.0  # PX4 BAT_LOW_THR/CRIT_THR/EMERGEN_THR
MAX_PEERS = 32  # parser states kept per UDP link (one per source address)
FORCE_DISARM_MAGIC = 21196.0  # MAVLink: param2 of COMPONENT_ARM_DISARM forcing it

SEV_CRITICAL = const("MAV_SEVERITY_CRITICAL")
SEV_WARNING = const("MAV_SEVERITY_WARNING")
SEV_INFO = const("MAV_SEVERITY_INFO")
SEV_EMERGENCY = const("MAV_SEVERITY_EMERGENCY")

R_ACCEPTED = const("MAV_RESULT_ACCEPTED")
R_TEMP_REJECTED = const("MAV_RESULT_TEMPORARILY_REJECTED")
R_DENIED = const("MAV_RESULT_DENIED")
R_UNSUPPORTED = const("MAV_RESULT_UNSUPPORTED")
R_FAILED = const("MAV_RESULT_FAILED")

# Internal flight modes (strings are what `Vehicle.mode` returns). LOITER is ArduCopter's
# LOITER: it follows the RC throttle, which without a transmitter sits at its minimum, so the
# copter descends (HOLD is BRAKE there: position and altitude kept).
HOLD, MISSION, RTL, LAND, TAKEOFF, GUIDED, POSCTL, LOITER = (
    "HOLD",
    "MISSION",
    "RTL",
    "LAND",
    "TAKEOFF",
    "GUIDED",
    "POSCTL",
    "LOITER",
)
AUTO_MODES = frozenset({HOLD, MISSION, RTL, LAND, TAKEOFF, GUIDED})

# PX4: custom_mode = main << 16 | sub << 24
PX4_MAIN_MANUAL, PX4_MAIN_ALTCTL, PX4_MAIN_POSCTL, PX4_MAIN_AUTO = 1, 2, 3, 4
PX4_SUB = {TAKEOFF: 2, HOLD: 3, MISSION: 4, RTL: 5, LAND: 6}
PX4_SUB_TO_MODE = {v: k for k, v in PX4_SUB.items()}
# ArduCopter: STABILIZE 0 (its boot mode), AUTO 3, GUIDED 4, LOITER 5, RTL 6, LAND 9, BRAKE 17
COPTER_MODES = {
    MISSION: 3,
    GUIDED: 4,
    HOLD: 17,
    LOITER: 5,
    RTL: 6,
    LAND: 9,
    TAKEOFF: 4,
    POSCTL: 0,
}
COPTER_NUM_TO_MODE = {0: POSCTL, 3: MISSION, 4: GUIDED, 5: LOITER, 6: RTL, 9: LAND, 17: HOLD}
PLANE_MODES = {MISSION: 10, RTL: 11, HOLD: 12, GUIDED: 15, TAKEOFF: 13, LAND: 10, POSCTL: 12}
PLANE_NUM_TO_MODE = {10: MISSION, 11: RTL, 12: HOLD, 15: GUIDED, 13: TAKEOFF, 1: HOLD}

# Streams a link can carry; ArduPilot REQUEST_DATA_STREAM groups map onto them.
STREAMS = (
    "HEARTBEAT",
    "GLOBAL_POSITION_INT",
    "GPS_RAW_INT",
    "SYS_STATUS",
    "BATTERY_STATUS",
    "EXTENDED_SYS_STATE",
    "HOME_POSITION",
    "MISSION_CURRENT",
    "ATTITUDE",
    "SYSTEM_TIME",
    "VFR_HUD",
)
AP_STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    2: ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT"),  # MAV_DATA_STREAM_EXTENDED_STATUS
    6: ("GLOBAL_POSITION_INT",),  # POSITION
    10: ("ATTITUDE",),  # EXTRA1
    11: ("VFR_HUD",),  # EXTRA2
    12: ("BATTERY_STATUS", "SYSTEM_TIME", "EXTENDED_SYS_STATE", "HOME_POSITION"),  # EXTRA3
}
REQUESTABLE = (*STREAMS, "AUTOPILOT_VERSION")

SENSORS_PRESENT = (
    const("MAV_SYS_STATUS_SENSOR_3D_GYRO")
    | const("MAV_SYS_STATUS_SENSOR_3D_ACCEL")
    | const("MAV_SYS_STATUS_SENSOR_3D_MAG")
    | const("MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE")
    | const("MAV_SYS_STATUS_SENSOR_GPS")
    | const("MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS")
    | const("MAV_SYS_STATUS_SENSOR_BATTERY")
    | const("MAV_SYS_STATUS_SENSOR_PROPULSION")
)
SENSOR_GPS = const("MAV_SYS_STATUS_SENSOR_GPS")
SENSOR_MOTORS = const("MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS") | const(
    "MAV_SYS_STATUS_SENSOR_PROPULSION"
)
SENSOR_BATTERY = const("MAV_SYS_STATUS_SENSOR_BATTERY")

COUNTER_NAMES = (
    "rx_datagrams",
    "rx_messages",
    "tx_messages",
    "garbage",
    "bad_crc",
    "bad_frame",
    "truncated",
    "unknown_msgid",
    "rejected_unsigned",
    "rejected_bad_signature",
    "dropped_other_sysid",
    "dropped_other_compid",
    "unsupported_cmd",
    "unhandled_msg",
    "handler_errors",
    "uploads_ok",
    "uploads_failed",
    "mission_rerequests",
    "mission_bad_seq",
    "mission_duplicate_item",
    "mission_repeated_ack",
    "mission_unexpected_item",
    "commands",
    "dropped_link_loss",
    "dropped_packet_loss",
    "delayed_latency",
)


def mission_items_from_specs(
    specs: tuple[MissionItemSpec, ...], *, ardupilot: bool, home: tuple[float, float, float]
) -> list[mp.RawItem]:
    """Preloaded mission: DO_CHANGE_SPEED before each waypoint with a speed; AMSL frame;
    ArduPilot gets its home as item 0."""
    out: list[mp.RawItem] = []

    def add(  # noqa: PLR0917 - mirrors MISSION_ITEM_INT's field order
        cmd: int, frame: int, p1: float, p2: float, p3: float, x: int, y: int, z: float
    ) -> None:
        out.append(
            mp.RawItem(
                len(out),
                frame,
                cmd,
                0,
                1,
                p1,
                p2,
                p3,
                math.nan if frame != mp.FRAME_MISSION else 0.0,
                x,
                y,
                z,
            )
        )

    if ardupilot:
        add(
            mp.CMD_WAYPOINT,
            mp.FRAME_GLOBAL_INT,
            0,
            0,
            0,
            round(home[0] * 1e7),
            round(home[1] * 1e7),
            home[2],
        )
    for s in specs:
        if s.speed_mps is not None:
            add(mp.CMD_CHANGE_SPEED, mp.FRAME_MISSION, 1.0, s.speed_mps, -1.0, 0, 0, 0.0)
        acc = s.acceptance_radius_m if s.acceptance_radius_m is not None else 0.0
        add(
            mp.CMD_WAYPOINT,
            mp.FRAME_GLOBAL_INT,
            0.0,
            acc,
            0.0,
            round(s.lat_deg * 1e7),
            round(s.lon_deg * 1e7),
            s.alt_amsl_m,
        )
    return out


@dataclass(slots=True)
class _Stream:
    period_s: float  # simulated seconds; <= 0: off
    next_due_s: float = 0.0
    last_real_s: float = 0.0


class _Link:
    """A MAVLink channel of the vehicle with its own sequence numbers and stream set."""

    name: str

    def __init__(
        self, vehicle: Vehicle, name: str, rates_hz: dict[str, float], link_id: int = 0
    ) -> None:
        self.vehicle = vehicle
        self.name = name
        # signing: one signing link id per channel, as PX4 (its MAVLink instance number)
        self.encoder = Encoder(vehicle.sys_id, 1, key=vehicle.signing_key, link_id=link_id)
        self.streams: dict[str, _Stream] = {
            n: _Stream(1.0 / hz if hz > 0 else 0.0) for n, hz in rates_hz.items()
        }
        self.closed = False

    def set_rate(self, stream: str, hz: float) -> None:
        st = self.streams.setdefault(stream, _Stream(0.0))
        st.period_s = 1.0 / hz if hz > 0 else 0.0
        st.next_due_s = 0.0

    def send(self, name: str, **fields: Any) -> None:
        if self.closed:
            return
        data = self.encoder.pack(name, **fields)
        self.vehicle._out(self, data)

    def transmit(self, data: bytes) -> None:  # pragma: no cover - overridden
        raise NotImplementedError


class _UdpLink(_Link, asyncio.DatagramProtocol):
    def __init__(
        self,
        vehicle: Vehicle,
        name: str,
        rates_hz: dict[str, float],
        remote: tuple[str, int],
        link_id: int = 0,
    ) -> None:
        _Link.__init__(self, vehicle, name, rates_hz, link_id)
        self.remote = remote
        self.remote_learned = False
        self.transport: asyncio.DatagramTransport | None = None
        self.parsers: dict[tuple[str, int], Parser] = {}

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Python 3.11's selector datagram transport does not subclass DatagramTransport.
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        peer = (str(addr[0]), int(addr[1]))
        self.vehicle._in(self, data, peer)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when nobody listens on the GCS port: normal before a GCS starts.
        self.vehicle.counters["link_errors"] = self.vehicle.counters.get("link_errors", 0) + 1

    def parser_for(self, peer: tuple[str, int]) -> Parser:
        p = self.parsers.get(peer)
        if p is None:
            if len(self.parsers) >= MAX_PEERS:
                self.parsers.pop(next(iter(self.parsers)))
            p = self.parsers[peer] = Parser(self.vehicle.signing_key)
        return p

    def transmit(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.sendto(data, self.remote)

    @property
    def local_port(self) -> int:
        if self.transport is None:
            return 0
        return int(self.transport.get_extra_info("sockname")[1])


class _TcpLink(_Link, asyncio.Protocol):
    def __init__(self, vehicle: Vehicle, rates_hz: dict[str, float]) -> None:
        _Link.__init__(self, vehicle, "tcp", rates_hz, link_id=2)
        self.transport: asyncio.Transport | None = None
        self.parser = Parser(vehicle.signing_key)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.vehicle._links.append(self)

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed = True
        with contextlib.suppress(ValueError):
            self.vehicle._links.remove(self)

    def data_received(self, data: bytes) -> None:
        self.vehicle._in(self, data, None)

    def transmit(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)


@dataclass(slots=True)
class _FaultState:
    spec: FaultSpec
    active: bool = False
    done: bool = False


class Vehicle:
    """A PX4-like (or ArduPilot-like) vehicle. Read-only state is exposed for tests/reports."""

    def __init__(self, spec: VehicleSpec, sim_time: SimTime, *, t0_elapsed_s: float = 0.0) -> None:
        self.spec = spec
        self._clock = sim_time
        self._t0 = t0_elapsed_s
        self.sys_id = spec.system_id
        self.signing_key = spec.signing_key_bytes()
        # signing on: message name -> count of incoming messages dropped for their signature
        self.rejected_messages: dict[str, int] = {}
        self.is_ardupilot = spec.autopilot == ARDUPILOT
        self.is_fixed_wing = spec.kind == FIXED_WING
        self.lim = spec.limits()
        self._frame = LocalTangent(spec.home_lat_deg, spec.home_lon_deg)
        self.home = (spec.home_lat_deg, spec.home_lon_deg, spec.home_alt_amsl_m)
        self.ground_alt_m = spec.home_alt_amsl_m
        self.k = KinState(alt_amsl_m=spec.home_alt_amsl_m)
        self._rng = random.Random(spec.seed * 1000003 + self.sys_id)
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.statustexts: list[tuple[float, int, str]] = []
        self.position_history: list[tuple[float, float, float, float]] = []
        self._links: list[_Link] = []
        self._udp: _UdpLink | None = None
        self._api: _UdpLink | None = None
        self._tcp_server: asyncio.Server | None = None
        self._t = 0.0  # simulated s since fleet start, last advanced to
        self._booted = False
        self._next_history_t = 0.0
        # flight state (ArduCopter boots in STABILIZE)
        self._mode = POSCTL if self.is_ardupilot and not self.is_fixed_wing else HOLD
        self._armed = False
        self._landed = True
        self._armed_at = 0.0
        self._landed_at = 0.0
        self._goal_ne: tuple[float, float] = (0.0, 0.0)
        self._goal_alt = spec.home_alt_amsl_m
        self._speed_override: float | None = None
        self._rtl_phase = 0
        self._rtl_alt = spec.home_alt_amsl_m + spec.rtl_alt_rel_m
        self._takeoff_alt = spec.home_alt_amsl_m + spec.takeoff_alt_rel_m
        self._jam_rate = DEFAULT_FAULT_VALUE[FaultKind.GNSS_JAMMING]
        self.takeoff_alt_rel_m = spec.takeoff_alt_rel_m
        self.rtl_alt_rel_m = spec.rtl_alt_rel_m
        self.cruise_mps = self.lim.cruise_speed_mps
        # mission
        self._items: list[mp.RawItem] = mission_items_from_specs(
            spec.mission, ardupilot=self.is_ardupilot, home=self.home
        )
        self._seq = 1 if self.is_ardupilot and self._items else 0
        self._mission_state = (
            const("MISSION_STATE_NOT_STARTED") if self._items else const("MISSION_STATE_NO_MISSION")
        )
        self._item_reached_at: float | None = None
        self._carry_goal: tuple[float, float, float] | None = (
            None  # ArduPilot: target kept over an upload
        )
        self._stalled = False  # ArduPilot: a replaced mission's current item failed to restart
        self._mission_climb = False
        self._mission_speed: float | None = None
        self.mission_server = mp.MissionServer(
            self, max_items=spec.max_mission_items, ardupilot=spec.autopilot == ARDUPILOT
        )
        # faults
        self._faults = [_FaultState(f) for f in spec.faults]
        self._jam_since: float | None = None
        self._jam_offset = (0.0, 0.0)
        self._jam_dir = self._rng.uniform(0.0, 2.0 * math.pi)
        self._spoof_north_m = 0.0
        self._drain_pct_s = 0.0
        self._link_loss = False
        self._packet_loss = 0.0
        self._latency_s = 0.0
        self._motor_failed = False
        self.battery_pct = 100.0
        self._bat_level = 0  # 0 ok, 1 low, 2 critical, 3 emergency
        self._auto_started = False
        self._params: dict[str, float] = {
            "MIS_TAKEOFF_ALT": self.takeoff_alt_rel_m,
            "RTL_RETURN_ALT": self.rtl_alt_rel_m,
            "NAV_ACC_RAD": self.lim.acceptance_radius_m,
            "MPC_XY_CRUISE": self.cruise_mps,
            "FW_AIRSPD_TRIM": self.cruise_mps,
        }

    # ------------------------------------------------------------------ read-only state
    @property
    def lat_deg(self) -> float:
        return self._frame.to_latlon(self.k.north_m, self.k.east_m)[0]

    @property
    def lon_deg(self) -> float:
        return self._frame.to_latlon(self.k.north_m, self.k.east_m)[1]

    @property
    def alt_amsl_m(self) -> float:
        return self.k.alt_amsl_m

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def landed(self) -> bool:
        return self._landed

    @property
    def mission(self) -> tuple[mp.RawItem, ...]:
        return tuple(self._items)

    @property
    def mission_current_seq(self) -> int:
        return self._seq

    @property
    def local_port(self) -> int:
        return self._udp.local_port if self._udp is not None else 0

    @property
    def api_local_port(self) -> int:
        return self._api.local_port if self._api is not None else 0

    @property
    def tcp_port(self) -> int:
        if self._tcp_server is None or not self._tcp_server.sockets:
            return 0
        return int(self._tcp_server.sockets[0].getsockname()[1])

    @property
    def motor_failed(self) -> bool:
        return self._motor_failed

    def reported_position(self) -> tuple[float, float, float]:
        """Position as telemetry reports it (spoofing offset, jamming drift; without noise)."""
        n = self.k.north_m + self._spoof_north_m + self._jam_offset[0]
        e = self.k.east_m + self._jam_offset[1]
        lat, lon = self._frame.to_latlon(n, e)
        return lat, lon, self.k.alt_amsl_m

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        spec = self.spec
        streaming = dict(spec.stream_rates_hz)
        if self.is_ardupilot:
            # ArduPilot streams nothing but HEARTBEAT until asked (SRx_ params at 0).
            streaming = {"HEARTBEAT": streaming.get("HEARTBEAT", 1.0)}
        want_udp = not self.is_ardupilot or spec.bind_port is not None
        if want_udp:
            port = spec.bind_port if spec.bind_port is not None else 18570 + spec.instance
            link = _UdpLink(self, "gcs", streaming, (spec.gcs_host, spec.gcs_port))
            await loop.create_datagram_endpoint(lambda: link, local_addr=(spec.bind_host, port))
            self._udp = link
            self._links.append(link)
        if spec.api_link:
            port = spec.api_bind_port if spec.api_bind_port is not None else 18580 + spec.instance
            # PX4's API link binds 14580+i: keep the convention unless a port is given.
            if spec.api_bind_port is None:
                port = 14580 + spec.instance
            remote = (
                spec.gcs_host,
                spec.api_port if spec.api_port is not None else 14540 + spec.instance,
            )
            api = _UdpLink(self, "api", streaming, remote, link_id=1)
            await loop.create_datagram_endpoint(lambda: api, local_addr=(spec.bind_host, port))
            self._api = api
            self._links.append(api)
        if self.is_ardupilot:
            tport = spec.tcp_port if spec.tcp_port is not None else 5760 + 10 * spec.instance
            self._tcp_server = await loop.create_server(
                lambda: _TcpLink(self, {"HEARTBEAT": 1.0}), host=spec.bind_host, port=tport
            )

    async def stop(self) -> None:
        for link in list(self._links):
            link.closed = True
            tr = getattr(link, "transport", None)
            if tr is not None:
                tr.close()
        self._links.clear()
        if self._tcp_server is not None:
            self._tcp_server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._tcp_server.wait_closed(), 1.0)

    # ------------------------------------------------------------------ time
    def sim_now_utc_s(self) -> float:
        return self._clock.start_utc_s + self._t0 + self._t

    def _time_boot_ms(self) -> int:
        return max(0, int((self._t - self.spec.boot_at_s) * 1000.0))

    # ------------------------------------------------------------------ I/O with faults
    def _out(self, link: _Link, data: bytes) -> None:
        if not self._booted:
            return
        if self._link_loss:
            self.counters["dropped_link_loss"] += 1
            return
        if self._packet_loss > 0 and self._rng.random() < self._packet_loss:
            self.counters["dropped_packet_loss"] += 1
            return
        self.counters["tx_messages"] += 1
        if self._latency_s > 0:
            self.counters["delayed_latency"] += 1
            asyncio.get_running_loop().call_later(
                self._clock.real_delay_s(self._latency_s), link.transmit, data
            )
        else:
            link.transmit(data)

    def _in(self, link: _Link, data: bytes, peer: tuple[str, int] | None) -> None:
        if not self._booted:
            return
        self.counters["rx_datagrams"] += 1
        if self._link_loss:
            self.counters["dropped_link_loss"] += 1
            return
        if self._packet_loss > 0 and self._rng.random() < self._packet_loss:
            self.counters["dropped_packet_loss"] += 1
            return
        if self._latency_s > 0:
            self.counters["delayed_latency"] += 1
            asyncio.get_running_loop().call_later(
                self._clock.real_delay_s(self._latency_s), self._receive, link, data, peer
            )
        else:
            self._receive(link, data, peer)

    def _receive(self, link: _Link, data: bytes, peer: tuple[str, int] | None) -> None:
        try:
            if isinstance(link, _UdpLink) and peer is not None:
                res = link.parser_for(peer).parse_datagram(data)
            elif isinstance(link, _TcpLink):
                res = link.parser.parse_stream(data)
            else:
                return
            c = self.counters
            c["garbage"] += res.garbage
            c["bad_crc"] += res.bad_crc
            c["bad_frame"] += res.bad_frame
            c["truncated"] += res.truncated
            c["unknown_msgid"] += res.unknown_msgid
            if res.rejected_msg_ids:
                c["rejected_unsigned"] += res.unsigned_rejected
                c["rejected_bad_signature"] += res.bad_signature
                for mid in res.rejected_msg_ids:
                    name = name_of(mid) or f"MSG_{mid}"
                    self.rejected_messages[name] = self.rejected_messages.get(name, 0) + 1
            if (
                res.messages
                and isinstance(link, _UdpLink)
                and peer is not None
                and not link.remote_learned
            ):
                # As PX4: the first peer that talks to us becomes the reply address.
                link.remote = peer
                link.remote_learned = True
            for m in res.messages:
                c["rx_messages"] += 1
                try:
                    self._handle(link, m)
                except Exception:
                    c["handler_errors"] += 1
                    _log.exception("sysid %d: error handling %s", self.sys_id, m.type)
        except Exception:
            self.counters["handler_errors"] += 1
            _log.exception("sysid %d: error receiving", self.sys_id)

    def _broadcast(self, name: str, **fields: Any) -> None:
        for link in list(self._links):
            link.send(name, **fields)

    # MissionHost protocol -------------------------------------------------------------
    def send(self, peer: object, name: str, **fields: Any) -> None:
        if isinstance(peer, _Link):
            peer.send(name, **fields)

    def count(self, counter: str) -> None:
        self.counters[counter] = self.counters.get(counter, 0) + 1

    def statustext(self, severity: int, text: str) -> None:
        self.statustexts.append((self.sim_now_utc_s(), severity, text))
        _log.info("sysid %d: %s", self.sys_id, text)
        self._broadcast("STATUSTEXT", severity=severity, text=text.encode()[:50])

    def mission_items(self) -> list[mp.RawItem]:
        if self.is_ardupilot and self._items:
            home = mp.RawItem(
                0,
                mp.FRAME_GLOBAL_INT,
                mp.CMD_WAYPOINT,
                0,
                1,
                0,
                0,
                0,
                0,
                round(self.home[0] * 1e7),
                round(self.home[1] * 1e7),
                self.home[2],
            )
            return [home, *self._items[1:]]
        return list(self._items)

    def accept_mission(self, items: list[mp.RawItem], flagged_current: int | None) -> None:
        flying_mission = self._mode == MISSION and self._armed and not self._landed
        old_seq = self._seq
        if self.is_ardupilot:
            items = [mp.ardupilot_stored(it, fixed_wing=self.is_fixed_wing) for it in items]
            flagged_current = None  # ArduPilot ignores the current flag of an upload
        else:
            items = [mp.px4_stored(it) for it in items]
        self._items = items
        first = 1 if self.is_ardupilot else 0
        self._stalled = False
        if flagged_current is not None:
            self._seq = max(first, flagged_current)
        elif flying_mission:
            # PX4 keeps the current index; ArduPilot restarts the command at the same index,
            # which fails on a DO item: the vehicle then holds until told another item
            self._seq = min(old_seq, len(items) - 1)
            if self.is_ardupilot and items[self._seq].command not in mp.NAV_COMMANDS:
                self._stalled = True
                self.statustext(SEV_WARNING, "Auto mission changed but failed to restart command")
            elif self.is_ardupilot:
                self.statustext(SEV_INFO, "Auto mission changed, restarted command")
        else:
            self._seq = first
        self._seq = max(0, min(self._seq, len(items) - 1))
        self._item_reached_at = None
        self._mission_state = (
            const("MISSION_STATE_ACTIVE") if flying_mission else const("MISSION_STATE_NOT_STARTED")
        )
        self._send_mission_current()

    def clear_mission(self) -> None:
        self._items = []
        self._seq = 0
        self._carry_goal = None
        self._mission_state = const("MISSION_STATE_NO_MISSION")
        if self._mode == MISSION and not self._landed:
            self._enter_hold()
        self._send_mission_current()

    def set_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self._items) or (self.is_ardupilot and seq == 0):
            return False
        self._seq = seq
        self._item_reached_at = None
        self._carry_goal = None
        self._stalled = False
        self._send_mission_current()
        return True

    # ------------------------------------------------------------------ message handling
    def _handle(self, link: _Link, m: Inbound) -> None:
        if m.has("target_system"):
            ts = m.i("target_system")
            if ts not in (0, self.sys_id):
                self.counters["dropped_other_sysid"] += 1
                return
            if m.has("target_component") and m.i("target_component") not in (0, 1):
                self.counters["dropped_other_compid"] += 1
                return
        t = m.type
        if t == "HEARTBEAT":
            return
        if self.mission_server.handle(link, m, time.monotonic()):
            return
        if t in ("COMMAND_LONG", "COMMAND_INT"):
            self.counters["commands"] += 1
            self._on_command(link, m)
        elif t == "SET_MODE":
            self._set_mode_numbers(m.i("base_mode"), m.i("custom_mode"))
        elif t == "REQUEST_DATA_STREAM":
            self._on_request_data_stream(link, m)
        elif t == "PARAM_REQUEST_LIST":
            for i, name in enumerate(self._params):
                self._send_param(link, name, i)
        elif t == "PARAM_REQUEST_READ":
            self._on_param_read(link, m)
        elif t == "PARAM_SET":
            self._on_param_set(link, m)
        elif t == "TIMESYNC":
            if m.i("tc1") == 0:
                link.send("TIMESYNC", tc1=int(self.sim_now_utc_s() * 1e9), ts1=m.i("ts1"))
        elif t in ("SYSTEM_TIME", "COMMAND_ACK", "STATUSTEXT", "PING"):
            return
        else:
            self.counters["unhandled_msg"] += 1

    def _send_param(self, link: _Link, name: str, index: int) -> None:
        link.send(
            "PARAM_VALUE",
            param_id=name.encode(),
            param_value=float(self._params[name]),
            param_type=const("MAV_PARAM_TYPE_REAL32"),
            param_count=len(self._params),
            param_index=index,
        )

    def _on_param_read(self, link: _Link, m: Inbound) -> None:
        names = list(self._params)
        idx = m.i("param_index")
        name = m.text("param_id")
        if idx >= 0 and idx < len(names) and idx != 65535 and not name:
            name = names[idx]
        if name in self._params:
            self._send_param(link, name, names.index(name))

    def _on_param_set(self, link: _Link, m: Inbound) -> None:
        name = m.text("param_id")
        if name not in self._params:
            return
        value = m.f("param_value")
        self._params[name] = value
        if name == "MIS_TAKEOFF_ALT":
            self.takeoff_alt_rel_m = value
        elif name == "RTL_RETURN_ALT":
            self.rtl_alt_rel_m = value
        elif name in ("MPC_XY_CRUISE", "FW_AIRSPD_TRIM"):
            self.cruise_mps = value
        self._send_param(link, name, list(self._params).index(name))

    def _on_request_data_stream(self, link: _Link, m: Inbound) -> None:
        sid, rate, on = m.i("req_stream_id"), m.i("req_message_rate"), m.i("start_stop")
        if sid == 0:
            names: tuple[str, ...] = tuple(n for g in AP_STREAM_GROUPS.values() for n in g)
        else:
            names = AP_STREAM_GROUPS.get(sid, ())
        for n in names:
            link.set_rate(n, float(rate) if on else 0.0)

    def _ack(self, link: _Link, m: Inbound, command: int, result: int) -> None:
        link.send(
            "COMMAND_ACK",
            command=command,
            result=result,
            progress=0,
            result_param2=0,
            target_system=m.src_system,
            target_component=m.src_component,
        )

    def _on_command(self, link: _Link, m: Inbound) -> None:
        cmd = m.i("command")
        p = (
            [m.f(f"param{i}") for i in range(1, 8)]
            if m.type == "COMMAND_LONG"
            else [
                m.f("param1"),
                m.f("param2"),
                m.f("param3"),
                m.f("param4"),
                m.i("x") / 1e7,
                m.i("y") / 1e7,
                m.f("z"),
            ]
        )
        handler = self._command_table().get(cmd)
        if handler is None:
            self.counters["unsupported_cmd"] += 1
            self._ack(link, m, cmd, R_UNSUPPORTED)
            return
        result = handler(link, m, p)
        if result is not None:
            self._ack(link, m, cmd, result)

    def _command_table(self) -> dict[int, Callable[[_Link, Inbound, list[float]], int | None]]:
        return {
            const("MAV_CMD_DO_SET_MODE"): self._cmd_set_mode,
            const("MAV_CMD_COMPONENT_ARM_DISARM"): self._cmd_arm,
            const("MAV_CMD_NAV_TAKEOFF"): self._cmd_takeoff,
            const("MAV_CMD_NAV_LAND"): self._cmd_land,
            const("MAV_CMD_DO_LAND_START"): self._cmd_land_start,
            const("MAV_CMD_NAV_RETURN_TO_LAUNCH"): lambda _l, _m, _p: self._request_mode(RTL),
            const("MAV_CMD_MISSION_START"): self._cmd_mission_start,
            const("MAV_CMD_DO_REPOSITION"): self._cmd_reposition,
            const("MAV_CMD_DO_CHANGE_SPEED"): self._cmd_change_speed,
            const("MAV_CMD_REQUEST_MESSAGE"): self._cmd_request_message,
            const("MAV_CMD_SET_MESSAGE_INTERVAL"): self._cmd_set_interval,
            const("MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES"): self._cmd_capabilities,
            const("MAV_CMD_DO_SET_MISSION_CURRENT"): lambda _l, _m, p: (
                R_ACCEPTED if self.set_current(int(p[0])) else R_DENIED
            ),
            const("MAV_CMD_GET_HOME_POSITION"): self._cmd_home,
            const("MAV_CMD_INJECT_FAILURE"): self._cmd_inject_failure,
        }

    def _cmd_set_mode(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        base = int(p[0])
        if self.is_ardupilot:
            return self._set_mode_numbers(base, int(p[1]))
        return self._set_mode_numbers(base, (int(p[1]) << 16) | (int(p[2]) << 24))

    def _set_mode_numbers(self, base_mode: int, custom_mode: int) -> int:
        if self.is_ardupilot:
            table = PLANE_NUM_TO_MODE if self.is_fixed_wing else COPTER_NUM_TO_MODE
            target = table.get(custom_mode)
        else:
            main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
            if main == PX4_MAIN_AUTO:
                target = PX4_SUB_TO_MODE.get(sub)
            elif main in (PX4_MAIN_MANUAL, PX4_MAIN_ALTCTL, PX4_MAIN_POSCTL):
                target = POSCTL
            else:
                target = None
        if target is None:
            return R_UNSUPPORTED
        return self._request_mode(target)

    def _request_mode(self, target: str) -> int:
        if self._motor_failed and target != LAND:
            self.statustext(SEV_CRITICAL, "Mode change denied: motor failure")
            return R_DENIED
        if target == MISSION and not self._items:
            self.statustext(SEV_CRITICAL, "Mode change denied: no valid mission")
            return R_DENIED
        if target == TAKEOFF and not self._armed:
            self.statustext(SEV_CRITICAL, "Takeoff denied: disarmed")
            return R_DENIED
        self._enter_mode(target)
        return R_ACCEPTED

    def _cmd_arm(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        force = p[1] == FORCE_DISARM_MAGIC
        if p[0] >= 0.5:
            return self.arm(force=force)
        if not self._landed and not force:
            self.statustext(SEV_CRITICAL, "Disarming denied: not landed")
            return R_DENIED
        self._disarm()
        return R_ACCEPTED

    def arm(self, *, force: bool = False) -> int:
        if self._armed:
            return R_ACCEPTED
        if not force:
            if self._motor_failed:
                self.statustext(SEV_CRITICAL, "Preflight Fail: motor failure")
                return R_DENIED
            if self._gps_fix_type() < 3:
                self.statustext(SEV_CRITICAL, "Preflight Fail: GPS fix too low")
                return R_DENIED
            if self.battery_pct < BAT_EMERG_PCT:
                self.statustext(SEV_CRITICAL, "Preflight Fail: battery unhealthy")
                return R_DENIED
        self._armed = True
        self._armed_at = self._t
        self.statustext(SEV_INFO, "Armed by external command")
        return R_ACCEPTED

    def _disarm(self) -> None:
        if self._armed:
            self._armed = False
            self.statustext(
                SEV_INFO, "Disarmed by external command" if not self._landed else "Disarmed"
            )

    def _cmd_takeoff(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        # param7: PX4 takes the altitude AMSL, ArduPilot metres above home
        alt = p[6] + self.ground_alt_m if self.is_ardupilot else p[6]
        if math.isfinite(alt) and alt > self.ground_alt_m:
            self._takeoff_alt = alt
        else:
            self._takeoff_alt = self.ground_alt_m + self.takeoff_alt_rel_m
        if not self._armed:
            self.statustext(SEV_CRITICAL, "Takeoff denied: disarmed")
            return R_DENIED
        return self._request_mode(TAKEOFF)

    def _cmd_land(self, _l: _Link, _m: Inbound, _p: list[float]) -> int:
        if self.is_ardupilot and self.is_fixed_wing:
            return R_UNSUPPORTED  # ArduPlane lands through a mission (DO_LAND_START)
        return self._request_mode(LAND)

    def _cmd_land_start(self, _l: _Link, _m: Inbound, _p: list[float]) -> int:
        """Jump to the mission's landing sequence (its DO_LAND_START item) in mission mode;
        FAILED without one, as ArduPlane."""
        first = 1 if self.is_ardupilot else 0
        seq = next(
            (
                i
                for i in range(first, len(self._items))
                if self._items[i].command == mp.CMD_LAND_START
            ),
            None,
        )
        if seq is None:
            self.statustext(SEV_WARNING, "Unable to start landing sequence")
            return R_FAILED
        result = self._request_mode(MISSION)
        if result == R_ACCEPTED:
            self.set_current(seq)
        return result

    def _cmd_mission_start(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        if not self._items:
            return R_DENIED
        first = int(p[0])
        if 0 < first < len(self._items):
            self._seq = first
        return self._request_mode(MISSION)

    def _cmd_reposition(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        if self._motor_failed:
            return R_DENIED
        lat, lon, alt = p[4], p[5], p[6]
        if not (math.isfinite(lat) and math.isfinite(lon)) or (lat == 0 and lon == 0):
            n, e = self.k.north_m, self.k.east_m
        elif not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return R_DENIED
        else:
            n, e = self._frame.to_ne(lat, lon)
        if p[0] > 0:
            self._speed_override = p[0]
        self._enter_mode(GUIDED if self.is_ardupilot else HOLD)
        self._goal_ne = (n, e)
        self._goal_alt = alt if math.isfinite(alt) else self.k.alt_amsl_m
        return R_ACCEPTED

    def _cmd_change_speed(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        if p[1] == -2:
            self._speed_override = None
            self._mission_speed = None
        elif p[1] > 0:
            self._speed_override = p[1]
            self._mission_speed = p[1]
        return R_ACCEPTED

    def _cmd_request_message(self, link: _Link, m: Inbound, p: list[float]) -> int | None:
        name = name_of(int(p[0]))
        if name is None or name not in REQUESTABLE:
            return R_UNSUPPORTED
        self._ack(link, m, const("MAV_CMD_REQUEST_MESSAGE"), R_ACCEPTED)
        self._send_stream(link, name)
        return None

    def _cmd_capabilities(self, link: _Link, m: Inbound, _p: list[float]) -> int | None:
        self._ack(link, m, const("MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES"), R_ACCEPTED)
        self._send_stream(link, "AUTOPILOT_VERSION")
        return None

    def _cmd_home(self, link: _Link, m: Inbound, _p: list[float]) -> int | None:
        self._ack(link, m, const("MAV_CMD_GET_HOME_POSITION"), R_ACCEPTED)
        self._send_stream(link, "HOME_POSITION")
        return None

    def _cmd_set_interval(self, link: _Link, _m: Inbound, p: list[float]) -> int:
        name = name_of(int(p[0]))
        if name is None or name not in STREAMS:
            return R_UNSUPPORTED
        interval_us = p[1]
        if interval_us < 0:
            link.set_rate(name, 0.0)
        elif interval_us == 0:
            link.set_rate(name, dict(self.spec.stream_rates_hz).get(name, 1.0))
        else:
            link.set_rate(name, 1e6 / interval_us)
        return R_ACCEPTED

    def _cmd_inject_failure(self, _l: _Link, _m: Inbound, p: list[float]) -> int:
        unit, ftype = int(p[0]), int(p[1])
        off = ftype == const("FAILURE_TYPE_OFF")
        kinds = {
            const("FAILURE_UNIT_SENSOR_GPS"): FaultKind.GNSS_JAMMING,
            const("FAILURE_UNIT_SYSTEM_MOTOR"): FaultKind.MOTOR_FAILURE,
            const("FAILURE_UNIT_SYSTEM_BATTERY"): FaultKind.BATTERY_DROP,
            const("FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL"): FaultKind.LINK_LOSS,
        }
        kind = kinds.get(unit)
        if kind is None:
            return R_UNSUPPORTED
        if ftype == const("FAILURE_TYPE_OK"):
            for f in self._faults:
                if f.spec.kind == kind and f.active:
                    f.done = True
            return R_ACCEPTED
        if not off and kind != FaultKind.GNSS_JAMMING:
            return R_UNSUPPORTED
        self.inject_fault(kind, duration_s=None if kind != FaultKind.LINK_LOSS else 10.0)
        return R_ACCEPTED

    # ------------------------------------------------------------------ faults
    def inject_fault(
        self, kind: FaultKind, *, duration_s: float | None = None, value: float | None = None
    ) -> None:
        """Start a fault now (the "on command" path of fault injection)."""
        self._faults.append(
            _FaultState(FaultSpec(kind=kind, at_s=self._t, duration_s=duration_s, value=value))
        )
        self._update_faults()

    def _update_faults(self) -> None:
        t = self._t
        jam = False
        spoof = 0.0
        drain = 0.0
        link_loss = False
        ploss = 0.0
        latency = 0.0
        jam_rate = DEFAULT_FAULT_VALUE[FaultKind.GNSS_JAMMING]
        for f in self._faults:
            s = f.spec
            end = math.inf if s.duration_s is None else s.at_s + s.duration_s
            now_active = not f.done and s.at_s <= t < end
            value = s.value if s.value is not None else DEFAULT_FAULT_VALUE[s.kind]
            if now_active and not f.active:
                self._fault_started(s.kind, value)
            if f.active and not now_active:
                f.done = True
                self._fault_ended(s.kind)
            f.active = now_active
            if not now_active:
                continue
            if s.kind == FaultKind.GNSS_JAMMING:
                jam = True
                jam_rate = value
            elif s.kind == FaultKind.SPOOFING:
                spoof += value
            elif s.kind == FaultKind.BATTERY_DRAIN:
                drain += value
            elif s.kind == FaultKind.LINK_LOSS:
                link_loss = True
            elif s.kind == FaultKind.PACKET_LOSS:
                ploss = max(ploss, value)
            elif s.kind == FaultKind.LATENCY:
                latency = max(latency, value)
        if jam and self._jam_since is None:
            self._jam_since = t
        if not jam:
            self._jam_since = None
            self._jam_offset = (0.0, 0.0)
        self._jam_rate = jam_rate
        self._spoof_north_m = spoof
        self._drain_pct_s = drain
        self._link_loss = link_loss
        self._packet_loss = min(1.0, max(0.0, ploss))
        self._latency_s = max(0.0, latency)

    def _fault_started(self, kind: FaultKind, value: float) -> None:
        _log.info("sysid %d: fault %s starts (value %s)", self.sys_id, kind.name, value)
        if kind == FaultKind.GNSS_JAMMING:
            self.statustext(SEV_CRITICAL, "GNSS jamming detected: position degraded")
        elif kind == FaultKind.BATTERY_DROP:
            self.battery_pct = min(self.battery_pct, value)
        elif kind == FaultKind.MOTOR_FAILURE:
            self._motor_failed = True
            self.statustext(SEV_EMERGENCY, "Motor failure detected! Emergency landing")
            if self._armed and not self._landed:
                self._enter_mode(LAND)
        elif kind == FaultKind.LINK_LOSS:
            self.counters["link_loss_events"] = self.counters.get("link_loss_events", 0) + 1

    def _fault_ended(self, kind: FaultKind) -> None:
        _log.info("sysid %d: fault %s ends", self.sys_id, kind.name)
        if kind == FaultKind.GNSS_JAMMING:
            self.statustext(SEV_INFO, "GNSS recovered")

    def _jam_level(self) -> float:
        """0 (clean) .. 1 (fully jammed): jamming degrades the receiver over ~10 s."""
        if self._jam_since is None:
            return 0.0
        return min(1.0, (self._t - self._jam_since) / 10.0 + 0.1)

    def _gps_fix_type(self) -> int:
        lvl = self._jam_level()
        if lvl == 0.0:
            return 3
        if lvl < 0.4:
            return 3
        if lvl < 0.8:
            return 2
        return 1

    # ------------------------------------------------------------------ modes
    def _enter_hold(self) -> None:
        self._mode = GUIDED if self.is_ardupilot and self._mode == GUIDED else HOLD
        self._goal_ne = (self.k.north_m, self.k.east_m)
        self._goal_alt = self.k.alt_amsl_m if not self._landed else self.ground_alt_m

    def _enter_mode(self, target: str) -> None:
        prev = self._mode
        self._mode = target
        if target in (HOLD, POSCTL, GUIDED):
            self._goal_ne = (self.k.north_m, self.k.east_m)
            self._goal_alt = self.k.alt_amsl_m
        elif target in (LAND, LOITER):
            self._goal_ne = (self.k.north_m, self.k.east_m)
        elif target == RTL:
            self._rtl_phase = 0
        elif target == TAKEOFF:
            self._goal_ne = (self.k.north_m, self.k.east_m)
        elif target == MISSION:
            if self.is_ardupilot and self._seq == 0:
                self._seq = 1 if len(self._items) > 1 else 0
            self._mission_state = const("MISSION_STATE_ACTIVE")
            self._item_reached_at = None
            self._mission_climb = self._landed
        if target != MISSION and prev == MISSION and self._items:
            self._mission_state = const("MISSION_STATE_PAUSED")
        if prev != target:
            _log.info("sysid %d: mode %s -> %s", self.sys_id, prev, target)

    # ------------------------------------------------------------------ simulation
    def advance(self, t_s: float) -> None:
        """Advance the vehicle to `t_s` simulated seconds after fleet start."""
        if t_s < self.spec.boot_at_s:
            self._t = t_s
            return
        if not self._booted:
            self._booted = True
            self._t = max(self._t, self.spec.boot_at_s)
            self.statustext(
                SEV_INFO, "Ready for takeoff!" if not self.is_ardupilot else "ArduPilot Ready"
            )
        dt_total = t_s - self._t
        if dt_total > 0:
            n = max(1, math.ceil(dt_total / PHYSICS_DT_S - 1e-9))
            n = min(n, 400)  # after a long stall take bigger steps rather than freezing the loop
            dt = dt_total / n
            for _ in range(n):
                self._t += dt
                self._update_faults()
                self._auto_start()
                self._step(dt)
        self._t = t_s
        self.mission_server.tick(time.monotonic())
        if self._t >= self._next_history_t:
            self._next_history_t = self._t + HISTORY_PERIOD_S
            self.position_history.append(
                (self.sim_now_utc_s(), self.lat_deg, self.lon_deg, self.alt_amsl_m)
            )
        self._send_streams()

    def _auto_start(self) -> None:
        at = self.spec.auto_start_at_s
        if self._auto_started or at is None or self._t < at:
            return
        self._auto_started = True
        if self.arm() != R_ACCEPTED:
            return
        if self._items and self.spec.start_airborne:
            self._place_airborne()
        if self._items:
            self._enter_mode(MISSION)
        else:
            self._takeoff_alt = self.ground_alt_m + self.takeoff_alt_rel_m
            self._enter_mode(TAKEOFF)

    def _place_airborne(self) -> None:
        """Scenario start in flight: put the vehicle at its first mission waypoint, at its
        altitude, already moving towards the next one at the mission speed (see
        VehicleSpec.start_airborne)."""
        items = self._items
        first = 1 if self.is_ardupilot else 0
        navs = [i for i in range(first, len(items)) if items[i].command in mp.NAV_COMMANDS]
        if not navs:
            return
        i0 = navs[0]
        n0, e0, alt0 = self._item_target(items[i0])
        self.k.north_m, self.k.east_m, self.k.alt_amsl_m = n0, e0, alt0
        self._landed = False
        self._seq = i0
        speed = self.cruise_mps
        if len(navs) > 1:
            for it in items[i0 + 1 : navs[1]]:
                if it.command == mp.CMD_CHANGE_SPEED and it.param2 > 0:
                    speed = it.param2
            n1, e1, _alt1 = self._item_target(items[navs[1]])
            dist = math.hypot(n1 - n0, e1 - e0)
            if dist > 0.0:
                speed = min(speed, self.lim.max_speed_mps)
                self.k.yaw_rad = math.atan2(e1 - e0, n1 - n0)
                self.k.vn_mps = speed * (n1 - n0) / dist
                self.k.ve_mps = speed * (e1 - e0) / dist
                self.k.airspeed_mps = speed
        self.statustext(SEV_INFO, "Scenario start in flight")

    def _speed(self) -> float:
        v = self._speed_override or self._mission_speed or self.cruise_mps
        return min(v, self.lim.max_speed_mps)

    def _step(self, dt: float) -> None:
        self._battery(dt)
        if not self._armed:
            if not self._landed:  # disarmed in the air: falls
                self.k.vup_mps = max(self.k.vup_mps - 9.81 * dt, -30.0)
                self.k.alt_amsl_m += self.k.vup_mps * dt
                self._touchdown_check()
            return
        if (
            self._landed
            and self._t - self._armed_at > DISARM_PREFLIGHT_S
            and self._mode not in (TAKEOFF, MISSION)
        ):
            self.statustext(SEV_INFO, "Disarmed by auto preflight disarming")
            self._armed = False
            return
        goal = self._mode_goal()
        if goal is None:
            return
        if self._landed:
            if goal.alt_amsl_m <= self.ground_alt_m + 0.3:
                if self._t - self._landed_at > DISARM_AFTER_LAND_S and self._mode == LAND:
                    self._armed = False
                    self.statustext(SEV_INFO, "Landing detected, disarmed")
                return
            self._landed = False
            self.statustext(SEV_INFO, "Takeoff detected")
            if self.is_fixed_wing:
                self.k.airspeed_mps = self.lim.min_airspeed_mps
        if self.is_fixed_wing:
            step_fixed_wing(
                self.k, goal, self.lim, dt, (self.spec.wind_north_mps, self.spec.wind_east_mps)
            )
        else:
            step_multirotor(self.k, goal, self.lim, dt)
        self._touchdown_check()

    def _touchdown_check(self) -> None:
        if self.k.alt_amsl_m <= self.ground_alt_m and self.k.vup_mps <= 0.0:
            self.k.alt_amsl_m = self.ground_alt_m
            self.k.vn_mps = self.k.ve_mps = self.k.vup_mps = 0.0
            self.k.roll_rad = self.k.pitch_rad = 0.0
            self.k.airspeed_mps = 0.0
            if not self._landed:
                self._landed = True
                self._landed_at = self._t
                if self._mode == MISSION:
                    self._mission_state = const("MISSION_STATE_COMPLETE")
                    self._mode = LAND  # lands are finished by the land logic (auto-disarm)

    def _battery(self, dt: float) -> None:
        rate = 0.0
        if self._armed:
            rate = 100.0 / self.spec.battery_capacity_s * (1.0 if not self._landed else 0.3)
        self.battery_pct = max(0.0, self.battery_pct - (rate + self._drain_pct_s) * dt)
        level = (
            3
            if self.battery_pct < BAT_EMERG_PCT
            else 2
            if self.battery_pct < BAT_CRIT_PCT
            else 1
            if self.battery_pct < BAT_LOW_PCT
            else 0
        )
        if level > self._bat_level:
            self._bat_level = level
            flying = self._armed and not self._landed
            if level == 1:
                self.statustext(SEV_WARNING, "Low battery level! Return advised")
            elif level == 2:
                self.statustext(SEV_CRITICAL, "Critical battery level! Executing RTL")
                if flying and self._mode not in (LAND, RTL):
                    self._enter_mode(RTL)
            else:
                self.statustext(SEV_EMERGENCY, "Emergency battery level! Landing immediately")
                if flying and self._mode != LAND:
                    self._enter_mode(LAND)

    def _goal(
        self,
        n: float,
        e: float,
        alt: float,
        *,
        stop: bool,
        speed: float | None = None,
        descent: float | None = None,
    ) -> Goal:
        return Goal(n, e, alt, self._speed() if speed is None else speed, stop, descent)

    def _mode_goal(self) -> Goal | None:
        mode = self._mode
        if mode in (HOLD, POSCTL, GUIDED):
            return self._goal(self._goal_ne[0], self._goal_ne[1], self._goal_alt, stop=True)
        if mode == TAKEOFF:
            alt = self._takeoff_alt
            if self.k.alt_amsl_m >= alt - 0.5:
                self._enter_mode(GUIDED if self.is_ardupilot else HOLD)
                self.statustext(SEV_INFO, "Takeoff complete")
                return self._mode_goal()
            if self.is_fixed_wing:
                # climb out straight ahead, far target along the heading
                n = self.k.north_m + 1000.0 * math.cos(self.k.yaw_rad)
                e = self.k.east_m + 1000.0 * math.sin(self.k.yaw_rad)
                return self._goal(n, e, alt + 1.0, stop=False)
            return self._goal(self._goal_ne[0], self._goal_ne[1], alt + 0.6, stop=True)
        if mode == LOITER:  # ArduCopter LOITER at minimum RC throttle: straight down
            return self._goal(
                self._goal_ne[0],
                self._goal_ne[1],
                self.ground_alt_m - 1.0,
                stop=True,
                descent=self.lim.descent_rate_mps,
            )
        if mode == LAND:
            descent = self.lim.descent_rate_mps * (1.7 if self._motor_failed else 1.0)
            speed = self.lim.min_airspeed_mps if self.is_fixed_wing else self._speed()
            return self._goal(
                self._goal_ne[0],
                self._goal_ne[1],
                self.ground_alt_m - 1.0,
                stop=True,
                speed=speed,
                descent=descent,
            )
        if mode == RTL:
            return self._rtl_goal()
        if mode == MISSION:
            return self._mission_goal()
        return None

    def _rtl_goal(self) -> Goal:
        rtl_alt = max(self.k.alt_amsl_m, self.ground_alt_m + self.rtl_alt_rel_m)
        if self._rtl_phase == 0:
            self._rtl_alt = rtl_alt
            self._rtl_phase = 1
        if self._rtl_phase == 1:
            if self.k.alt_amsl_m < self._rtl_alt - 1.0 and not self.is_fixed_wing:
                return self._goal(self.k.north_m, self.k.east_m, self._rtl_alt, stop=True)
            self._rtl_phase = 2
        dist = math.hypot(self.k.north_m, self.k.east_m)
        if self.is_fixed_wing:
            return self._goal(0.0, 0.0, self._rtl_alt, stop=True)  # loiter over home
        if self._rtl_phase == 2 and dist > 1.0:
            return self._goal(0.0, 0.0, self._rtl_alt, stop=True)
        self._rtl_phase = 3
        return self._goal(0.0, 0.0, self.ground_alt_m - 1.0, stop=True)

    def _item_target(self, it: mp.RawItem) -> tuple[float, float, float]:
        if it.x == 0 and it.y == 0:
            n, e = self.k.north_m, self.k.east_m
        else:
            n, e = self._frame.to_ne(it.lat_deg, it.lon_deg)
        alt = it.z if math.isfinite(it.z) else self.k.alt_amsl_m
        if it.frame in mp.RELATIVE_FRAMES:
            alt += self.home[2]
        return n, e, alt

    def _mission_goal(self) -> Goal:
        items = self._items
        first = 1 if self.is_ardupilot else 0
        if self._mission_state == const("MISSION_STATE_COMPLETE") or self._stalled:
            return self._goal(self._goal_ne[0], self._goal_ne[1], self._goal_alt, stop=True)
        # execute DO items until the next NAV item
        guard = 0
        while (
            self._seq < len(items)
            and items[self._seq].command not in mp.NAV_COMMANDS
            and guard < len(items)
        ):
            it = items[self._seq]
            if it.command == mp.CMD_CHANGE_SPEED and it.param2 > 0:
                self._mission_speed = it.param2
            self._seq += 1
            guard += 1
            self._send_mission_current()
        if self._seq >= len(items) or self._seq < first:
            self._seq = max(first, min(self._seq, len(items) - 1))
            self._mission_state = const("MISSION_STATE_COMPLETE")
            return self._goal(self._goal_ne[0], self._goal_ne[1], self._goal_alt, stop=True)
        it = items[self._seq]
        if self._carry_goal is not None:
            n, e, alt = self._carry_goal
        else:
            n, e, alt = self._item_target(it)
        if it.command == mp.CMD_TAKEOFF:
            n, e = self.k.north_m, self.k.east_m
            if not math.isfinite(it.z):
                alt = self.ground_alt_m + self.takeoff_alt_rel_m
        if self._mission_climb:
            climb_alt = max(alt, self.ground_alt_m + self.takeoff_alt_rel_m)
            if self.k.alt_amsl_m < climb_alt - 1.0:
                if self.is_fixed_wing:
                    return self._goal(n, e, climb_alt, stop=False)
                return self._goal(self.k.north_m, self.k.east_m, climb_alt, stop=True)
            self._mission_climb = False
        if it.command == mp.CMD_RTL and self._carry_goal is None:
            self._enter_mode(RTL)
            return self._rtl_goal()
        if it.command == mp.CMD_LAND and self._carry_goal is None:
            dist = math.hypot(n - self.k.north_m, e - self.k.east_m)
            if dist > self._acceptance(it) and not self.is_fixed_wing:
                return self._goal(n, e, self.k.alt_amsl_m, stop=True)
            return self._goal(
                n, e, self.ground_alt_m - 1.0, stop=True, descent=self.lim.descent_rate_mps
            )
        self._goal_ne, self._goal_alt = (n, e), alt
        dist = math.hypot(n - self.k.north_m, e - self.k.east_m)
        alt_ok = abs(alt - self.k.alt_amsl_m) <= (1.5 if not self.is_fixed_wing else 10.0)
        last_nav = not any(x.command in mp.NAV_COMMANDS for x in items[self._seq + 1 :])
        hold_s = it.param1 if it.command in (mp.CMD_WAYPOINT, mp.CMD_LOITER_TIME) else 0.0
        if it.command == mp.CMD_TAKEOFF:
            reached = self.k.alt_amsl_m >= alt - 1.0
        else:
            reached = dist <= self._acceptance(it) and alt_ok
        if it.command == mp.CMD_LOITER_UNLIM:
            reached = False
        if reached:
            if self._item_reached_at is None:
                self._item_reached_at = self._t
                self._broadcast("MISSION_ITEM_REACHED", seq=self._seq)
            if self._t - self._item_reached_at >= max(0.0, hold_s):
                self._item_reached_at = None
                self._carry_goal = None
                if last_nav:
                    self._mission_state = const("MISSION_STATE_COMPLETE")
                    self._seq = max(self._seq, len(items) - 1)
                    self.statustext(SEV_INFO, "Mission finished, loitering")
                    # stay on the last point: MISSION mode, COMPLETE
                    return self._goal(n, e, alt, stop=True)
                self._seq += 1
                self._send_mission_current()
        stop = last_nav or hold_s > 0 or it.command in (mp.CMD_LOITER_UNLIM, mp.CMD_LOITER_TIME)
        return self._goal(n, e, alt, stop=stop)

    def _acceptance(self, it: mp.RawItem) -> float:
        if it.command == mp.CMD_WAYPOINT and it.param2 > 0:
            return it.param2
        return self.lim.acceptance_radius_m

    # ------------------------------------------------------------------ telemetry
    def _send_mission_current(self) -> None:
        if self._booted:
            for link in list(self._links):
                if (
                    link.streams.get("MISSION_CURRENT", _Stream(0.0)).period_s > 0
                    or not self.is_ardupilot
                ):
                    self._send_stream(link, "MISSION_CURRENT")

    def _send_streams(self) -> None:
        if not self._booted:
            return
        now_real = time.monotonic()
        min_real = 1.0 / self.spec.max_real_stream_hz
        for link in list(self._links):
            for name, st in link.streams.items():
                if st.period_s <= 0 or self._t < st.next_due_s:
                    continue
                if now_real - st.last_real_s < min_real:
                    continue
                st.next_due_s = max(st.next_due_s + st.period_s, self._t)
                st.last_real_s = now_real
                self._send_stream(link, name)

    def _custom_mode(self) -> tuple[int, int]:
        mode = self._mode
        if self.is_ardupilot:
            table = PLANE_MODES if self.is_fixed_wing else COPTER_MODES
            return const("MAV_MODE_FLAG_CUSTOM_MODE_ENABLED") | 16, table[mode]
        if mode == POSCTL:
            return 1 | 16 | 64, PX4_MAIN_POSCTL << 16  # custom | stabilize | manual input
        return 1 | 4 | 8 | 16, (PX4_MAIN_AUTO << 16) | (
            PX4_SUB[HOLD if mode == GUIDED else mode] << 24
        )

    def _system_status(self) -> int:
        if self._motor_failed or self._bat_level >= 3:
            return const("MAV_STATE_EMERGENCY")
        if self._bat_level == 2 or self._jam_level() >= 0.8:
            return const("MAV_STATE_CRITICAL")
        return const("MAV_STATE_ACTIVE") if self._armed else const("MAV_STATE_STANDBY")

    def _health(self) -> int:
        h = SENSORS_PRESENT
        if self._jam_level() >= 0.4:
            h &= ~SENSOR_GPS
        if self._motor_failed:
            h &= ~SENSOR_MOTORS
        if self._bat_level >= 2:
            h &= ~SENSOR_BATTERY
        return h

    def _noisy_reported(self) -> tuple[float, float, float]:
        n = self.k.north_m + self._spoof_north_m + self._jam_offset[0]
        e = self.k.east_m + self._jam_offset[1]
        if self.spec.gnss_noise_m > 0:
            n += self._rng.gauss(0.0, self.spec.gnss_noise_m)
            e += self._rng.gauss(0.0, self.spec.gnss_noise_m)
        lat, lon = self._frame.to_latlon(n, e)
        return lat, lon, self.k.alt_amsl_m

    def _send_stream(self, link: _Link, name: str) -> None:
        k = self.k
        tb = self._time_boot_ms()
        if self._jam_since is not None:
            # reported position drifts at the jamming rate (dead reckoning on a degraded fix)
            step = self._jam_rate * 0.2 * self._jam_level()
            self._jam_dir += self._rng.gauss(0.0, 0.05)
            self._jam_offset = (
                self._jam_offset[0] + step * math.cos(self._jam_dir),
                self._jam_offset[1] + step * math.sin(self._jam_dir),
            )
        if name == "HEARTBEAT":
            base, custom = self._custom_mode()
            if self._armed:
                base |= const("MAV_MODE_FLAG_SAFETY_ARMED")
            mav_type = (
                const("MAV_TYPE_FIXED_WING") if self.is_fixed_wing else const("MAV_TYPE_QUADROTOR")
            )
            ap = (
                const("MAV_AUTOPILOT_ARDUPILOTMEGA")
                if self.is_ardupilot
                else const("MAV_AUTOPILOT_PX4")
            )
            link.send(
                "HEARTBEAT",
                type=mav_type,
                autopilot=ap,
                base_mode=base,
                custom_mode=custom,
                system_status=self._system_status(),
                mavlink_version=3,
            )
        elif name == "GLOBAL_POSITION_INT":
            lat, lon, alt = self._noisy_reported()
            link.send(
                "GLOBAL_POSITION_INT",
                time_boot_ms=tb,
                lat=round(lat * 1e7),
                lon=round(lon * 1e7),
                alt=round(alt * 1000),
                relative_alt=round((alt - self.home[2]) * 1000),
                vx=round(k.vn_mps * 100),
                vy=round(k.ve_mps * 100),
                vz=round(-k.vup_mps * 100),
                hdg=round(math.degrees(k.yaw_rad) % 360 * 100) % 36000,
            )
        elif name == "GPS_RAW_INT":
            lat, lon, alt = self._noisy_reported()
            lvl = self._jam_level()
            fix = self._gps_fix_type()
            hdop = 0.8 + 30.0 * lvl * lvl  # eph grows with the jamming level
            h_acc_m = 1.0 + self.spec.gnss_noise_m + 60.0 * lvl * lvl
            sats = max(0, round(14 - 12 * lvl))
            gs = math.hypot(k.vn_mps, k.ve_mps)
            link.send(
                "GPS_RAW_INT",
                time_usec=int(self.sim_now_utc_s() * 1e6),
                fix_type=fix,
                lat=round(lat * 1e7),
                lon=round(lon * 1e7),
                alt=round(alt * 1000),
                eph=min(65534, round(hdop * 100)),
                epv=min(65534, round((1.2 + 40 * lvl * lvl) * 100)),
                vel=round(gs * 100),
                cog=round(math.degrees(math.atan2(k.ve_mps, k.vn_mps)) % 360 * 100) % 36000,
                satellites_visible=sats,
                alt_ellipsoid=round((alt + 47.0) * 1000),
                h_acc=round(h_acc_m * 1000),
                v_acc=round(h_acc_m * 1500),
                vel_acc=round(300 + 2000 * lvl),
                hdg_acc=0,
                yaw=0,
            )
        elif name == "SYS_STATUS":
            mv, ca = self._battery_electrics()
            link.send(
                "SYS_STATUS",
                onboard_control_sensors_present=SENSORS_PRESENT,
                onboard_control_sensors_enabled=SENSORS_PRESENT,
                onboard_control_sensors_health=self._health(),
                load=250,
                voltage_battery=mv,
                current_battery=ca,
                battery_remaining=round(self.battery_pct),
                drop_rate_comm=0,
                errors_comm=self.counters["bad_crc"] + self.counters["garbage"] % 65535,
                errors_count1=0,
                errors_count2=0,
                errors_count3=0,
                errors_count4=0,
            )
        elif name == "BATTERY_STATUS":
            mv, ca = self._battery_electrics()
            cell = mv // 4
            charge = [
                const("MAV_BATTERY_CHARGE_STATE_OK"),
                const("MAV_BATTERY_CHARGE_STATE_LOW"),
                const("MAV_BATTERY_CHARGE_STATE_CRITICAL"),
                const("MAV_BATTERY_CHARGE_STATE_EMERGENCY"),
            ][self._bat_level]
            remaining_s = int(self.battery_pct / 100.0 * self.spec.battery_capacity_s)
            link.send(
                "BATTERY_STATUS",
                id=0,
                battery_function=const("MAV_BATTERY_FUNCTION_ALL"),
                type=const("MAV_BATTERY_TYPE_LIPO"),
                temperature=2500,
                voltages=[cell, cell, cell, cell, 65535, 65535, 65535, 65535, 65535, 65535],
                current_battery=ca,
                current_consumed=round((100.0 - self.battery_pct) * 50),
                energy_consumed=-1,
                battery_remaining=round(self.battery_pct),
                time_remaining=remaining_s,
                charge_state=charge,
            )
        elif name == "EXTENDED_SYS_STATE":
            if self._landed:
                landed = const("MAV_LANDED_STATE_ON_GROUND")
            elif self._mode == TAKEOFF:
                landed = const("MAV_LANDED_STATE_TAKEOFF")
            elif self._mode == LAND or (self._mode == RTL and self._rtl_phase == 3):
                landed = const("MAV_LANDED_STATE_LANDING")
            else:
                landed = const("MAV_LANDED_STATE_IN_AIR")
            link.send(
                "EXTENDED_SYS_STATE",
                vtol_state=const("MAV_VTOL_STATE_UNDEFINED"),
                landed_state=landed,
            )
        elif name == "HOME_POSITION":
            link.send(
                "HOME_POSITION",
                latitude=round(self.home[0] * 1e7),
                longitude=round(self.home[1] * 1e7),
                altitude=round(self.home[2] * 1000),
                x=0.0,
                y=0.0,
                z=0.0,
                q=[1.0, 0.0, 0.0, 0.0],
                approach_x=0.0,
                approach_y=0.0,
                approach_z=0.0,
                time_usec=int(self.sim_now_utc_s() * 1e6),
            )
        elif name == "MISSION_CURRENT":
            in_mission = 1 if self._mode == MISSION else 2
            link.send(
                "MISSION_CURRENT",
                seq=self._seq,
                total=len(self._items),
                mission_state=self._mission_state,
                mission_mode=in_mission if self._items else 0,
            )
        elif name == "ATTITUDE":
            link.send(
                "ATTITUDE",
                time_boot_ms=tb,
                roll=k.roll_rad,
                pitch=k.pitch_rad,
                yaw=k.yaw_rad,
                rollspeed=0.0,
                pitchspeed=0.0,
                yawspeed=0.0,
            )
        elif name == "SYSTEM_TIME":
            link.send(
                "SYSTEM_TIME", time_unix_usec=int(self.sim_now_utc_s() * 1e6), time_boot_ms=tb
            )
        elif name == "VFR_HUD":
            link.send(
                "VFR_HUD",
                airspeed=k.airspeed_mps,
                groundspeed=math.hypot(k.vn_mps, k.ve_mps),
                heading=round(math.degrees(k.yaw_rad) % 360) % 360,
                throttle=50 if self._armed else 0,
                alt=k.alt_amsl_m,
                climb=k.vup_mps,
            )
        elif name == "AUTOPILOT_VERSION":
            caps = (
                const("MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT")
                | const("MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT")
                | const("MAV_PROTOCOL_CAPABILITY_MISSION_INT")
                | const("MAV_PROTOCOL_CAPABILITY_COMMAND_INT")
                | const("MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT")
                | const("MAV_PROTOCOL_CAPABILITY_MAVLINK2")
            )
            version = (
                (1 << 24) | (15 << 16) | (4 << 8) | 255
            )  # 1.15.4 official, like the measured PX4
            link.send(
                "AUTOPILOT_VERSION",
                capabilities=caps,
                flight_sw_version=version,
                middleware_sw_version=0,
                os_sw_version=0,
                board_version=0,
                flight_custom_version=[0] * 8,
                middleware_custom_version=[0] * 8,
                os_custom_version=[0] * 8,
                vendor_id=0,
                product_id=0,
                uid=self.sys_id,
                uid2=[0] * 18,
            )

    def _battery_electrics(self) -> tuple[int, int]:
        """(pack millivolts, centiamps) of a 4S LiPo: 16.8 V full, 13.2 V empty."""
        mv = round((13.2 + 3.6 * self.battery_pct / 100.0) * 1000)
        ca = 0 if not self._armed else (1500 if self._landed else 2500)
        return mv, ca


def stream_msg_id(name: str) -> int:
    mid = msg_id_of(name)
    if mid is None:
        raise KeyError(name)
    return mid
