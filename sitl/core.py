"""What the parts of one simulated vehicle share: constants (modes, mode numbers, streams,
counters), the vehicle's simulated time (:class:`Timeline`) and what a part may tell the
ground (:class:`Announcer`).

The parts, each passed what it needs and none importing the vehicle: :mod:`sitl.faults`
(fault state and GNSS quality), :mod:`sitl.flight` (modes, mission execution, physics steps,
battery), :mod:`sitl.transport` (links, receive path), :mod:`sitl.telemetry` (streams),
:mod:`sitl.commands` (COMMAND_LONG/INT, parameters) and :mod:`sitl.mission` (the mission
protocol); :mod:`sitl.vehicle` holds them and drives them (``advance``).

Truth vs. report: `lat_deg`/`lon_deg`/`alt_amsl_m` are the true position; telemetry reports the
true position plus the spoofing offset, the jamming drift and the configured GNSS noise.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from sitl import mission as mp
from sitl._mav import const
from sitl.spec import MissionItemSpec, SimClock, VehicleSpec

PHYSICS_DT_S = 0.05  # 20 Hz of simulated time
HISTORY_PERIOD_S = 1.0  # position_history sampling, simulated s
DISARM_AFTER_LAND_S = 2.0  # PX4 COM_DISARM_LAND
DISARM_PREFLIGHT_S = 10.0  # PX4 COM_DISARM_PRFLT: armed on the ground without take-off
BAT_LOW_PCT, BAT_CRIT_PCT, BAT_EMERG_PCT = 15.0, 7.0, 3.0  # PX4 BAT_LOW_THR/CRIT_THR/EMERGEN_THR
FORCE_DISARM_MAGIC = 21196.0  # MAVLink: param2 of COMPONENT_ARM_DISARM forcing it

SEV_CRITICAL = const("MAV_SEVERITY_CRITICAL")
SEV_WARNING = const("MAV_SEVERITY_WARNING")
SEV_INFO = const("MAV_SEVERITY_INFO")
SEV_EMERGENCY = const("MAV_SEVERITY_EMERGENCY")

R_ACCEPTED = const("MAV_RESULT_ACCEPTED")
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


class Announcer(Protocol):
    """What a part of the vehicle tells the ground (the vehicle sends it on every link)."""

    def statustext(self, severity: int, text: str) -> None: ...

    def broadcast(self, name: str, **fields: Any) -> None: ...

    def mission_current_changed(self) -> None:
        """The current mission item or the mission state changed (MISSION_CURRENT)."""
        ...


class Timeline:
    """The simulated time of one vehicle: ``t_s`` (simulated s since fleet start, as far as
    the vehicle has advanced), whether it has booted, and the UTC and boot times it reports."""

    def __init__(self, spec: VehicleSpec, clock: SimClock, t0_elapsed_s: float) -> None:
        self._clock = clock
        self._t0 = t0_elapsed_s
        self.boot_at_s = spec.boot_at_s
        self.t_s = 0.0
        self.booted = False

    def sim_now_utc_s(self) -> float:
        return self._clock.start_utc_s + self._t0 + self.t_s

    def time_boot_ms(self) -> int:
        return max(0, int((self.t_s - self.boot_at_s) * 1000.0))

    def real_delay_s(self, sim_s: float) -> float:
        """Event-loop seconds that ``sim_s`` simulated seconds take."""
        return self._clock.real_delay_s(sim_s)
