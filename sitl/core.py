"""State of one simulated vehicle, and the constants its parts share (modes, mode numbers,
streams, counters). :class:`VehicleCore` holds the state; the behaviour is layered on it:
:mod:`sitl.flight` (modes, mission execution, physics steps), :mod:`sitl.faults`,
:mod:`sitl.telemetry` (streams), :mod:`sitl.commands` (COMMAND_LONG/INT, parameters) and
:mod:`sitl.vehicle` (links, receive path, ``advance``).

Truth vs. report: `lat_deg`/`lon_deg`/`alt_amsl_m` are the true position; telemetry reports the
true position plus the spoofing offset, the jamming drift and the configured GNSS noise.
"""

from __future__ import annotations

import asyncio
import logging
import math
import random
from dataclasses import dataclass
from typing import Any

from sitl import mission as mp
from sitl._mav import Inbound, const
from sitl.links import Link, UdpLink
from sitl.physics import KinState, LocalTangent
from sitl.spec import (
    ARDUPILOT,
    DEFAULT_FAULT_VALUE,
    FIXED_WING,
    FaultKind,
    FaultSpec,
    MissionItemSpec,
    SimClock,
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
    12: ("BATTERY_STATUS", "SYSTEM_TIME", "HOME_POSITION"),  # EXTRA3
}
# (ArduPilot 4.6 puts EXTENDED_SYS_STATE in no group: measured, with every group asked for, it
# sends it only once SET_MESSAGE_INTERVAL asks for it, as the hub does)
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
    specs: tuple[MissionItemSpec, ...],
    *,
    ardupilot: bool,
    home: tuple[float, float, float],
    fixed_wing: bool = False,
) -> list[mp.RawItem]:
    """Preloaded mission: DO_CHANGE_SPEED before each waypoint with a speed (an airspeed
    for a fixed wing, a ground speed otherwise); AMSL frame; ArduPilot gets its home as
    item 0."""
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
            kind = 0.0 if fixed_wing else 1.0  # speed type: airspeed / ground speed
            add(mp.CMD_CHANGE_SPEED, mp.FRAME_MISSION, kind, s.speed_mps, -1.0, 0, 0, 0.0)
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
class FaultState:
    spec: FaultSpec
    active: bool = False
    done: bool = False


class VehicleCore:
    """The state of a PX4-like (or ArduPilot-like) vehicle; read-only views for tests."""

    def __init__(self, spec: VehicleSpec, sim_time: SimClock, *, t0_elapsed_s: float = 0.0) -> None:
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
        self._links: list[Link] = []
        self._udp: UdpLink | None = None
        self._api: UdpLink | None = None
        self._tcp_server: asyncio.Server | None = None
        self._t = 0.0  # simulated s since fleet start, last advanced to
        self._booted = False
        self._next_history_t = 0.0
        self._init_flight(spec)
        self._init_mission(spec)
        self._init_faults(spec)
        self._params: dict[str, float] = {
            "MIS_TAKEOFF_ALT": self.takeoff_alt_rel_m,
            "RTL_RETURN_ALT": self.rtl_alt_rel_m,
            "NAV_ACC_RAD": self.lim.acceptance_radius_m,
            "MPC_XY_CRUISE": self.cruise_mps,
            "FW_AIRSPD_TRIM": self.cruise_mps,
            "RTL_AUTOLAND": 0.0,  # ArduPlane: arming refused with a DO_LAND_START while 0
        }

    def speed_item(self, it: mp.RawItem) -> float | None:
        """The speed a DO_CHANGE_SPEED item (or command params) sets, None when it sets
        none: ArduPlane takes a ground speed (type 1) as a minimum ground speed and keeps
        flying its airspeed; a fixed wing flies no slower than its minimum airspeed."""
        if it.command != mp.CMD_CHANGE_SPEED or it.param2 <= 0.0:
            return None
        if not self.is_fixed_wing:
            return it.param2
        if self.is_ardupilot and it.param1 == 1.0:
            return None
        return max(it.param2, self.lim.min_airspeed_mps)

    def _init_flight(self, spec: VehicleSpec) -> None:
        """Flight state at boot: on the ground, disarmed (ArduCopter boots in STABILIZE)."""
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
        self.takeoff_alt_rel_m = spec.takeoff_alt_rel_m
        self.rtl_alt_rel_m = spec.rtl_alt_rel_m
        self.cruise_mps = self.lim.cruise_speed_mps

    def _init_mission(self, spec: VehicleSpec) -> None:
        """The mission the vehicle boots with (ArduPilot: item 0 is home, current item 1)."""
        self._items: list[mp.RawItem] = mission_items_from_specs(
            spec.mission, ardupilot=self.is_ardupilot, home=self.home, fixed_wing=self.is_fixed_wing
        )
        self._seq = 1 if self.is_ardupilot and self._items else 0
        self._mission_state = (
            const("MISSION_STATE_NOT_STARTED") if self._items else const("MISSION_STATE_NO_MISSION")
        )
        self._item_reached_at: float | None = None
        self._stalled = False  # ArduPilot: a replaced mission's current item failed to restart
        self._mission_climb = False
        self._mission_speed: float | None = None

    def _init_faults(self, spec: VehicleSpec) -> None:
        """Fault injection state and what the faults act on (battery, links, GNSS)."""
        self._faults = [FaultState(f) for f in spec.faults]
        self._jam_rate = DEFAULT_FAULT_VALUE[FaultKind.GNSS_JAMMING]
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
    def motor_failed(self) -> bool:
        return self._motor_failed

    def reported_position(self) -> tuple[float, float, float]:
        """Position as telemetry reports it (spoofing offset, jamming drift; without noise)."""
        n = self.k.north_m + self._spoof_north_m + self._jam_offset[0]
        e = self.k.east_m + self._jam_offset[1]
        lat, lon = self._frame.to_latlon(n, e)
        return lat, lon, self.k.alt_amsl_m

    def sim_now_utc_s(self) -> float:
        return self._clock.start_utc_s + self._t0 + self._t

    def _time_boot_ms(self) -> int:
        return max(0, int((self._t - self.spec.boot_at_s) * 1000.0))

    def _broadcast(self, name: str, **fields: Any) -> None:
        for link in list(self._links):
            link.send(name, **fields)

    # MissionHost protocol -------------------------------------------------------------

    def send(self, peer: object, name: str, **fields: Any) -> None:
        if isinstance(peer, Link):
            peer.send(name, **fields)

    def count(self, counter: str) -> None:
        self.counters[counter] = self.counters.get(counter, 0) + 1

    def statustext(self, severity: int, text: str) -> None:
        self.statustexts.append((self.sim_now_utc_s(), severity, text))
        _log.info("sysid %d: %s", self.sys_id, text)
        self._broadcast("STATUSTEXT", severity=severity, text=text.encode()[:50])

    def _send_mission_current(self) -> None:
        """MISSION_CURRENT on every link (see sitl.telemetry)."""
        raise NotImplementedError

    def _ack(self, link: Link, m: Inbound, command: int, result: int) -> None:
        link.send(
            "COMMAND_ACK",
            command=command,
            result=result,
            progress=0,
            result_param2=0,
            target_system=m.src_system,
            target_component=m.src_component,
        )

    def _jam_level(self) -> float:
        """0 (clean) .. 1 (fully jammed): jamming degrades the receiver over ~10 s."""
        if self._jam_since is None:
            return 0.0
        return min(1.0, (self._t - self._jam_since) / 10.0 + 0.1)

    def _acquiring_gnss(self) -> bool:
        """No fix yet since boot (``VehicleSpec.gnss_fix_after_s``)."""
        return self._t - self.spec.boot_at_s < self.spec.gnss_fix_after_s

    def _gps_fix_type(self) -> int:
        if self._acquiring_gnss():
            return 0
        lvl = self._jam_level()
        if lvl == 0.0:
            return 3
        if lvl < 0.4:
            return 3
        if lvl < 0.8:
            return 2
        return 1
