"""Commands of a simulated vehicle: COMMAND_LONG / COMMAND_INT answered as PX4 or ArduPilot
answer them (mode numbers, arming checks, take-off, landing, DO_LAND_START, failure
injection), SET_MODE, parameters and TIMESYNC.

:class:`CommandHandler` acts on the parts it is given (flight, faults, telemetry); the vehicle
hands it every message the mission server does not take (:meth:`CommandHandler.handlers`)."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from sitl import ground
from sitl import mission as mp
from sitl._mav import Inbound, const
from sitl.core import (
    COPTER_NUM_TO_MODE,
    FORCE_DISARM_MAGIC,
    GUIDED,
    HOLD,
    LAND,
    MISSION,
    PLANE_NUM_TO_MODE,
    POSCTL,
    PX4_MAIN_ALTCTL,
    PX4_MAIN_AUTO,
    PX4_MAIN_MANUAL,
    PX4_MAIN_POSCTL,
    PX4_SUB_TO_MODE,
    R_ACCEPTED,
    R_DENIED,
    R_FAILED,
    R_UNSUPPORTED,
    RTL,
    SEV_CRITICAL,
    SEV_WARNING,
    TAKEOFF,
    Announcer,
    Timeline,
)
from sitl.executor import MissionExecutor
from sitl.faults import Faults
from sitl.flight import Flight
from sitl.links import Link, send_ack
from sitl.spec import FaultKind
from sitl.telemetry import Telemetry

_log = logging.getLogger(__name__)


MessageHandler = Callable[[Link, Inbound], None]


class CommandHandler:
    """Command and parameter handlers (see the module docstring)."""

    def __init__(
        self,
        *,
        time: Timeline,
        flight: Flight,
        mission: MissionExecutor,
        faults: Faults,
        telemetry: Telemetry,
        counters: dict[str, int],
        announce: Announcer,
        reboot: Callable[[], None],
    ) -> None:
        self._time = time
        self._reboot = reboot
        self._flight = flight
        self._mission = mission
        self._faults = faults
        self._telemetry = telemetry
        self._counters = counters
        self._announce = announce
        self.is_ardupilot = flight.is_ardupilot
        self.is_fixed_wing = flight.is_fixed_wing

    def handlers(self) -> dict[str, MessageHandler]:
        """The handler of each message type this part answers."""
        return {
            "COMMAND_LONG": self._on_command_message,
            "COMMAND_INT": self._on_command_message,
            "SET_MODE": self._on_set_mode,
            "REQUEST_DATA_STREAM": self._telemetry.on_request_data_stream,
            "PARAM_REQUEST_LIST": self._on_param_list,
            "PARAM_REQUEST_READ": self._on_param_read,
            "PARAM_SET": self._on_param_set,
            "TIMESYNC": self._on_timesync,
        }

    def _on_command_message(self, link: Link, m: Inbound) -> None:
        self._counters["commands"] += 1
        self._on_command(link, m)

    def _on_set_mode(self, _link: Link, m: Inbound) -> None:
        self.set_mode_numbers(m.i("base_mode"), m.i("custom_mode"))

    def _on_param_list(self, link: Link, _m: Inbound) -> None:
        for i, name in enumerate(self._flight.params):
            self._send_param(link, name, i)

    def _on_timesync(self, link: Link, m: Inbound) -> None:
        if m.i("tc1") == 0:
            link.send("TIMESYNC", tc1=int(self._time.sim_now_utc_s() * 1e9), ts1=m.i("ts1"))

    def _send_param(self, link: Link, name: str, index: int) -> None:
        link.send(
            "PARAM_VALUE",
            param_id=name.encode(),
            param_value=float(self._flight.params[name]),
            param_type=const("MAV_PARAM_TYPE_REAL32"),
            param_count=len(self._flight.params),
            param_index=index,
        )

    def _on_param_read(self, link: Link, m: Inbound) -> None:
        names = list(self._flight.params)
        idx = m.i("param_index")
        name = m.text("param_id")
        if idx >= 0 and idx < len(names) and idx != 65535 and not name:
            name = names[idx]
        if name in self._flight.params:
            self._send_param(link, name, names.index(name))

    def _on_param_set(self, link: Link, m: Inbound) -> None:
        name = m.text("param_id")
        if name not in self._flight.params:
            return
        value = m.f("param_value")
        self._flight.params[name] = value
        if name == "MIS_TAKEOFF_ALT":
            self._flight.takeoff_alt_rel_m = value
        elif name == "RTL_RETURN_ALT":
            self._flight.rtl_alt_rel_m = value
        elif name in ("MPC_XY_CRUISE", "FW_AIRSPD_TRIM"):
            self._flight.cruise_mps = value
        self._send_param(link, name, list(self._flight.params).index(name))

    def _on_command(self, link: Link, m: Inbound) -> None:
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
            self._counters["unsupported_cmd"] += 1
            send_ack(link, m, cmd, R_UNSUPPORTED)
            return
        result = handler(link, m, p)
        if result is not None:
            send_ack(link, m, cmd, result)

    def _command_table(self) -> dict[int, Callable[[Link, Inbound, list[float]], int | None]]:
        return {
            const("MAV_CMD_DO_SET_MODE"): self._cmd_set_mode,
            const("MAV_CMD_COMPONENT_ARM_DISARM"): self._cmd_arm,
            const("MAV_CMD_NAV_TAKEOFF"): self._cmd_takeoff,
            const("MAV_CMD_NAV_LAND"): self._cmd_land,
            const("MAV_CMD_DO_LAND_START"): self._cmd_land_start,
            const("MAV_CMD_NAV_RETURN_TO_LAUNCH"): lambda _l, _m, _p: self.request_mode(RTL),
            const("MAV_CMD_MISSION_START"): self._cmd_mission_start,
            const("MAV_CMD_DO_REPOSITION"): self._cmd_reposition,
            const("MAV_CMD_DO_CHANGE_SPEED"): self._cmd_change_speed,
            const("MAV_CMD_REQUEST_MESSAGE"): self._telemetry.cmd_request_message,
            const("MAV_CMD_SET_MESSAGE_INTERVAL"): self._telemetry.cmd_set_interval,
            const("MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES"): self._telemetry.cmd_capabilities,
            const("MAV_CMD_DO_SET_MISSION_CURRENT"): lambda _l, _m, p: (
                R_ACCEPTED if self._mission.set_current(int(p[0])) else R_DENIED
            ),
            const("MAV_CMD_GET_HOME_POSITION"): self._telemetry.cmd_home,
            const("MAV_CMD_INJECT_FAILURE"): self._cmd_inject_failure,
            const("MAV_CMD_DO_SET_HOME"): lambda _l, _m, p: ground.set_home(
                self._flight, self._faults, p, ardupilot=self.is_ardupilot
            ),
            const("MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN"): lambda _l, _m, p: ground.reboot(
                self._flight, self._reboot, p, ardupilot=self.is_ardupilot
            ),
        }

    def _cmd_set_mode(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        base = int(p[0])
        if self.is_ardupilot:
            return self.set_mode_numbers(base, int(p[1]))
        return self.set_mode_numbers(base, (int(p[1]) << 16) | (int(p[2]) << 24))

    def set_mode_numbers(self, base_mode: int, custom_mode: int) -> int:
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
        return self.request_mode(target)

    def request_mode(self, target: str) -> int:
        if self._faults.motor_failed and target != LAND:
            self._announce.statustext(SEV_CRITICAL, "Mode change denied: motor failure")
            return R_DENIED
        if target == MISSION and not self._mission.items:
            self._announce.statustext(SEV_CRITICAL, "Mode change denied: no valid mission")
            return R_DENIED
        # a mode is not refused for being disarmed (PX4's user mode intention, ArduPilot's
        # set_mode): a vehicle armed in TAKEOFF takes off
        self._flight.enter_mode(target)
        return R_ACCEPTED

    def _cmd_arm(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        force = p[1] == FORCE_DISARM_MAGIC
        if p[0] >= 0.5:
            return self._flight.arm(force=force)
        if not self._flight.landed and not force:
            self._announce.statustext(SEV_CRITICAL, "Disarming denied: not landed")
            return R_DENIED
        self._flight.disarm()
        return R_ACCEPTED

    def _cmd_takeoff(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        # param7: PX4 takes the altitude AMSL, ArduPilot metres above home
        alt = p[6] + self._flight.ground_alt_m if self.is_ardupilot else p[6]
        if math.isfinite(alt) and alt > self._flight.ground_alt_m:
            self._flight.takeoff_alt_m = alt
        else:
            self._flight.takeoff_alt_m = self._flight.ground_alt_m + self._flight.takeoff_alt_rel_m
        if not self._flight.armed and self.is_ardupilot:
            return R_FAILED  # ArduCopter's do_user_takeoff: not armed
        return self.request_mode(TAKEOFF)  # PX4: AUTO.TAKEOFF, armed or not

    def _cmd_land(self, _l: Link, _m: Inbound, _p: list[float]) -> int:
        if self.is_ardupilot and self.is_fixed_wing:
            return R_UNSUPPORTED  # ArduPlane lands through a mission (DO_LAND_START)
        return self.request_mode(LAND)

    def _cmd_land_start(self, _l: Link, _m: Inbound, _p: list[float]) -> int:
        """Jump to the mission's landing sequence (its DO_LAND_START item) in mission mode;
        FAILED without one, as ArduPlane."""
        first = 1 if self.is_ardupilot else 0
        seq = next(
            (
                i
                for i in range(first, len(self._mission.items))
                if self._mission.items[i].command == mp.CMD_LAND_START
            ),
            None,
        )
        if seq is None:
            self._announce.statustext(SEV_WARNING, "Unable to start landing sequence")
            return R_FAILED
        result = self.request_mode(MISSION)
        if result == R_ACCEPTED:
            self._mission.set_current(seq)
        return result

    def _cmd_mission_start(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        if not self._mission.items:
            return R_DENIED
        first = int(p[0])
        if 0 < first < len(self._mission.items):
            self._mission.seq = first
        return self.request_mode(MISSION)

    def _cmd_reposition(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        if self._faults.motor_failed:
            return R_DENIED
        lat, lon, alt = p[4], p[5], p[6]
        if not (math.isfinite(lat) and math.isfinite(lon)) or (lat == 0 and lon == 0):
            n, e = self._flight.k.north_m, self._flight.k.east_m
        elif not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return R_DENIED
        else:
            n, e = self._flight.frame.to_ne(lat, lon)
        if p[0] > 0:
            self._flight.speed_override = p[0]
        self._flight.enter_mode(GUIDED if self.is_ardupilot else HOLD)
        self._flight.goal_ne = (n, e)
        self._flight.goal_alt = alt if math.isfinite(alt) else self._flight.k.alt_amsl_m
        return R_ACCEPTED

    def _cmd_change_speed(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        if p[1] == -2:
            self._flight.speed_override = None
            self._mission.speed = None
        elif p[1] > 0:
            as_item = mp.RawItem(0, 2, mp.CMD_CHANGE_SPEED, 0, 1, p[0], p[1], p[2], 0, 0, 0, 0.0)
            speed = self._mission.speed_item(as_item)  # (the same rules as the mission item)
            if speed is not None:
                self._flight.speed_override = speed
                self._mission.speed = speed
        return R_ACCEPTED

    def _cmd_inject_failure(self, _l: Link, _m: Inbound, p: list[float]) -> int:
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
            self._faults.clear(kind)
            return R_ACCEPTED
        if not off and kind != FaultKind.GNSS_JAMMING:
            return R_UNSUPPORTED
        duration_s = None if kind != FaultKind.LINK_LOSS else 10.0
        self._faults.inject(kind, self._flight, duration_s=duration_s)
        return R_ACCEPTED
