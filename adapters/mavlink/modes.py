"""Flight modes: PX4 custom modes and ArduPilot mode numbers <-> :class:`FlightMode`, vehicle
types, and the commands that put a vehicle in a mode.

PX4 packs its mode in HEARTBEAT.custom_mode as ``main << 16 | sub << 24`` (measured on PX4
v1.15.4); DO_SET_MODE takes (param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, param2 = main,
param3 = sub). ArduPilot puts its mode number in custom_mode and DO_SET_MODE param2.

Hold is the mode that keeps the vehicle where it is without a pilot: PX4 AUTO.LOITER;
ArduCopter BRAKE (LOITER follows the RC throttle, which sits at its minimum without a
transmitter: the copter descends to the ground); ArduPlane LOITER (circles at altitude).
"""

from __future__ import annotations

from gcs_utm.messages import FlightMode
from gcs_utm.model import Autopilot, VehicleKind

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_INVALID = 8
MAV_AUTOPILOT_PX4 = 12

PX4_MAIN_AUTO = 4
PX4_SUB_LOITER = 3
PX4_SUB_MISSION = 4
PX4_SUB_RTL = 5

_PX4_MAIN: dict[int, FlightMode] = {
    1: FlightMode.MANUAL,  # MANUAL
    2: FlightMode.MANUAL,  # ALTCTL
    3: FlightMode.MANUAL,  # POSCTL
    5: FlightMode.MANUAL,  # ACRO
    6: FlightMode.OFFBOARD,
    7: FlightMode.MANUAL,  # STABILIZED
    8: FlightMode.MANUAL,  # RATTITUDE
}
_PX4_AUTO_SUB: dict[int, FlightMode] = {
    1: FlightMode.HOLD,  # READY
    2: FlightMode.TAKEOFF,
    3: FlightMode.HOLD,  # LOITER
    4: FlightMode.MISSION,
    5: FlightMode.RTL,
    6: FlightMode.LAND,
    7: FlightMode.RTL,  # RTGS
    8: FlightMode.GUIDED,  # FOLLOW_TARGET
    9: FlightMode.LAND,  # PRECLAND
    10: FlightMode.TAKEOFF,  # VTOL_TAKEOFF
}

# ArduPilot mode numbers (ArduCopter / ArduPlane "mode" parameter values).
COPTER_MODES: dict[FlightMode, int] = {
    FlightMode.MISSION: 3,  # AUTO
    FlightMode.GUIDED: 4,
    FlightMode.HOLD: 17,  # BRAKE: LOITER would descend without RC throttle
    FlightMode.RTL: 6,
    FlightMode.LAND: 9,
}
PLANE_MODES: dict[FlightMode, int] = {
    FlightMode.MISSION: 10,  # AUTO
    FlightMode.RTL: 11,
    FlightMode.HOLD: 12,  # LOITER
    FlightMode.GUIDED: 15,
    FlightMode.LAND: 20,  # QLAND (VTOL planes); a pure plane lands via DO_LAND_START
}
_COPTER_FROM: dict[int, FlightMode] = {v: k for k, v in COPTER_MODES.items()} | {
    0: FlightMode.MANUAL,
    1: FlightMode.MANUAL,
    2: FlightMode.MANUAL,
    5: FlightMode.HOLD,  # LOITER
    16: FlightMode.MANUAL,
    21: FlightMode.RTL,
}
_PLANE_FROM: dict[int, FlightMode] = {v: k for k, v in PLANE_MODES.items()} | {
    0: FlightMode.MANUAL,
    2: FlightMode.MANUAL,
    5: FlightMode.MANUAL,
    6: FlightMode.MANUAL,
    1: FlightMode.HOLD,
    21: FlightMode.RTL,
    17: FlightMode.MANUAL,
    13: FlightMode.TAKEOFF,
}

_MULTIROTOR_TYPES = frozenset({2, 3, 4, 13, 14, 15, 29, 35})
_FIXED_WING_TYPES = frozenset({1, 19, 20, 21, 22, 23, 24, 25})


def autopilot_from(code: int) -> Autopilot:
    if code == MAV_AUTOPILOT_PX4:
        return Autopilot.PX4
    if code == MAV_AUTOPILOT_ARDUPILOTMEGA:
        return Autopilot.ARDUPILOT
    return Autopilot.UNKNOWN


def kind_from(mav_type: int) -> VehicleKind | None:
    if mav_type in _MULTIROTOR_TYPES:
        return VehicleKind.MULTIROTOR
    if mav_type in _FIXED_WING_TYPES:
        return VehicleKind.FIXED_WING
    return None


def mode_from(autopilot: Autopilot, kind: VehicleKind | None, custom_mode: int) -> FlightMode:
    if autopilot is Autopilot.PX4:
        main = (custom_mode >> 16) & 0xFF
        sub = (custom_mode >> 24) & 0xFF
        if main == PX4_MAIN_AUTO:
            return _PX4_AUTO_SUB.get(sub, FlightMode.UNKNOWN)
        return _PX4_MAIN.get(main, FlightMode.UNKNOWN)
    if autopilot is Autopilot.ARDUPILOT:
        table = _PLANE_FROM if kind is VehicleKind.FIXED_WING else _COPTER_FROM
        return table.get(custom_mode, FlightMode.UNKNOWN)
    return FlightMode.UNKNOWN


def set_mode_params(
    autopilot: Autopilot, kind: VehicleKind | None, mode: FlightMode
) -> tuple[float, float, float] | None:
    """DO_SET_MODE (param1, param2, param3) for ``mode``, or None when there is no such mode."""
    if autopilot is Autopilot.ARDUPILOT:
        table = PLANE_MODES if kind is VehicleKind.FIXED_WING else COPTER_MODES
        number = table.get(mode)
        return None if number is None else (1.0, float(number), 0.0)
    sub = {
        FlightMode.HOLD: PX4_SUB_LOITER,
        FlightMode.MISSION: PX4_SUB_MISSION,
        FlightMode.RTL: PX4_SUB_RTL,
    }.get(mode)
    return None if sub is None else (1.0, float(PX4_MAIN_AUTO), float(sub))
