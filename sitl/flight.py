"""Flight of a simulated vehicle: modes and their goals, take-off/landing detection, battery,
arming, and one physics step.

:class:`Flight` holds the kinematic state, the mode, the goal and the flight parameters, and
its :class:`sitl.executor.MissionExecutor` (the mission and its progress), whose current item
gives the goal in mission mode. It reads the fault state (:class:`sitl.faults.Faults`) and
tells the ground through an :class:`sitl.core.Announcer`; it is the
:class:`sitl.faults.FaultTarget` of the faults."""

from __future__ import annotations

import logging
import math

from sitl import mission as mp
from sitl._mav import const
from sitl.core import (
    BAT_CRIT_PCT,
    BAT_EMERG_PCT,
    BAT_LOW_PCT,
    DISARM_AFTER_LAND_S,
    DISARM_PREFLIGHT_S,
    GUIDED,
    HOLD,
    LAND,
    LOITER,
    MISSION,
    POSCTL,
    R_ACCEPTED,
    R_DENIED,
    R_FAILED,
    RTL,
    SEV_CRITICAL,
    SEV_EMERGENCY,
    SEV_INFO,
    SEV_WARNING,
    TAKEOFF,
    Announcer,
    Timeline,
)
from sitl.executor import MissionExecutor
from sitl.faults import Faults
from sitl.physics import (
    Goal,
    KinState,
    LocalTangent,
    step_fixed_wing,
    step_multirotor,
)
from sitl.spec import ARDUPILOT, FIXED_WING, VehicleSpec

_log = logging.getLogger(__name__)


class Flight:
    """Modes, goals and physics (see the module docstring)."""

    def __init__(
        self, *, spec: VehicleSpec, time: Timeline, faults: Faults, announce: Announcer
    ) -> None:
        self.spec = spec
        self._time = time
        self._faults = faults
        self._announce = announce
        self.sys_id = spec.system_id
        self.is_ardupilot = spec.autopilot == ARDUPILOT
        self.is_fixed_wing = spec.kind == FIXED_WING
        self.lim = spec.limits()
        self.frame = LocalTangent(spec.home_lat_deg, spec.home_lon_deg)
        self.home = (spec.home_lat_deg, spec.home_lon_deg, spec.home_alt_amsl_m)
        self.ground_alt_m = spec.home_alt_amsl_m
        # set by DO_SET_HOME: PX4's manual home, ArduPilot's locked home, kept at arming
        self.home_manual = False
        self.k = KinState(alt_amsl_m=spec.home_alt_amsl_m)
        self.battery_pct = 100.0
        self.bat_level = 0  # 0 ok, 1 low, 2 critical, 3 emergency
        self._auto_started = False
        self._init_flight(spec)
        self.mission = MissionExecutor(
            spec=spec, time=time, k=self.k, frame=self.frame, announce=announce
        )
        self.params: dict[str, float] = {
            "MIS_TAKEOFF_ALT": self.takeoff_alt_rel_m,
            "RTL_RETURN_ALT": self.rtl_alt_rel_m,
            "NAV_ACC_RAD": self.lim.acceptance_radius_m,
            "MPC_XY_CRUISE": self.cruise_mps,
            "FW_AIRSPD_TRIM": self.cruise_mps,
            "RTL_AUTOLAND": 0.0,  # ArduPlane: arming refused with a DO_LAND_START while 0
        }

    def _init_flight(self, spec: VehicleSpec) -> None:
        """Flight state at boot: on the ground, disarmed (ArduCopter boots in STABILIZE)."""
        self.mode = POSCTL if self.is_ardupilot and not self.is_fixed_wing else HOLD
        self.armed = False
        self.landed = True
        self._armed_at = 0.0
        self._landed_at = 0.0
        self.goal_ne: tuple[float, float] = (0.0, 0.0)
        self.goal_alt = spec.home_alt_amsl_m
        self.speed_override: float | None = None
        self.rtl_phase = 0
        self._rtl_alt = spec.home_alt_amsl_m + spec.rtl_alt_rel_m
        self.takeoff_alt_m = spec.home_alt_amsl_m + spec.takeoff_alt_rel_m
        self.takeoff_alt_rel_m = spec.takeoff_alt_rel_m
        self.rtl_alt_rel_m = spec.rtl_alt_rel_m
        self.cruise_mps = self.lim.cruise_speed_mps

    def reboot(self) -> None:
        """The autopilot restarts (:meth:`sitl.vehicle.Vehicle.reboot`): disarmed in its boot
        mode, no scenario auto-start, parameters kept; its home is taken again where it
        stands (both set home at the first fix after boot) and is automatic again."""
        self.armed = False
        self.mode = POSCTL if self.is_ardupilot and not self.is_fixed_wing else HOLD
        self.speed_override = None
        self.rtl_phase = 0
        self.goal_ne = (self.k.north_m, self.k.east_m)
        self.goal_alt = self.k.alt_amsl_m if not self.landed else self.ground_alt_m
        self._auto_started = True
        self.set_home(
            self.lat_deg, self.lon_deg, self.ground_alt_m if self.landed else self.k.alt_amsl_m
        )
        self.home_manual = False
        self.mission.reboot()

    def set_home(self, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> None:
        """Home, as HOME_POSITION reports it and RTL and relative altitudes use it."""
        self.home = (lat_deg, lon_deg, alt_amsl_m)
        self.mission.home = self.home

    @property
    def lat_deg(self) -> float:
        return self.frame.to_latlon(self.k.north_m, self.k.east_m)[0]

    @property
    def lon_deg(self) -> float:
        return self.frame.to_latlon(self.k.north_m, self.k.east_m)[1]

    # FaultTarget ---------------------------------------------------------------------

    def drop_battery(self, pct: float) -> None:
        self.battery_pct = min(self.battery_pct, pct)

    def land_now(self) -> None:
        if self.armed and not self.landed:
            self.enter_mode(LAND)

    # Mission uploads (the flight's side: a stalled restart holds) ------------------------

    def accept_mission(self, items: list[mp.RawItem], flagged_current: int | None) -> None:
        flying = self.mode == MISSION and self.armed and not self.landed
        if self.mission.accept(items, flagged_current, flying=flying):
            self.goal_ne = (self.k.north_m, self.k.east_m)  # stalled: hold here
            self.goal_alt = self.k.alt_amsl_m

    def clear_mission(self) -> None:
        self.mission.clear()
        if self.mode == MISSION and not self.landed:
            self._enter_hold()
        self._announce.mission_current_changed()

    def _enter_hold(self) -> None:
        self.mode = GUIDED if self.is_ardupilot and self.mode == GUIDED else HOLD
        self.goal_ne = (self.k.north_m, self.k.east_m)
        self.goal_alt = self.k.alt_amsl_m if not self.landed else self.ground_alt_m

    def enter_mode(self, target: str) -> None:
        prev = self.mode
        self.mode = target
        if target in (HOLD, POSCTL, GUIDED):
            self.goal_ne = (self.k.north_m, self.k.east_m)
            self.goal_alt = self.k.alt_amsl_m
        elif target in (LAND, LOITER):
            self.goal_ne = (self.k.north_m, self.k.east_m)
        elif target == RTL:
            self.rtl_phase = 0
        elif target == TAKEOFF:
            self.goal_ne = (self.k.north_m, self.k.east_m)
        elif target == MISSION:
            self.mission.start(on_ground=self.landed)
        if target != MISSION and prev == MISSION:
            self.mission.pause()
        if prev != target:
            _log.info("sysid %d: mode %s -> %s", self.sys_id, prev, target)

    def auto_start(self) -> None:
        at = self.spec.auto_start_at_s
        if self._auto_started or at is None or self._time.t_s < at:
            return
        self._auto_started = True
        if self.arm() != R_ACCEPTED:
            return
        if self.mission.items and self.spec.start_airborne:
            self._place_airborne()
        if self.mission.items:
            self.enter_mode(MISSION)
        else:
            self.takeoff_alt_m = self.ground_alt_m + self.takeoff_alt_rel_m
            self.enter_mode(TAKEOFF)

    def _place_airborne(self) -> None:
        """Scenario start in flight: put the vehicle at its first mission waypoint, at its
        altitude, already moving towards the next one at the mission speed (see
        VehicleSpec.start_airborne)."""
        items = self.mission.items
        first = 1 if self.is_ardupilot else 0
        navs = [i for i in range(first, len(items)) if items[i].command in mp.NAV_COMMANDS]
        if not navs:
            return
        i0 = navs[0]
        n0, e0, alt0 = self.mission.item_target(items[i0])
        self.k.north_m, self.k.east_m, self.k.alt_amsl_m = n0, e0, alt0
        self.landed = False
        self.mission.seq = i0
        speed = self.cruise_mps
        if len(navs) > 1:
            for it in items[i0 + 1 : navs[1]]:
                speed = self.mission.speed_item(it) or speed
            n1, e1, _alt1 = self.mission.item_target(items[navs[1]])
            dist = math.hypot(n1 - n0, e1 - e0)
            if dist > 0.0:
                speed = min(speed, self.lim.max_speed_mps)
                self.k.yaw_rad = math.atan2(e1 - e0, n1 - n0)
                self.k.vn_mps = speed * (n1 - n0) / dist
                self.k.ve_mps = speed * (e1 - e0) / dist
                self.k.airspeed_mps = speed
        self._announce.statustext(SEV_INFO, "Scenario start in flight")

    def _speed(self) -> float:
        v = self.speed_override or self.mission.speed or self.cruise_mps
        return min(v, self.lim.max_speed_mps)

    def step(self, dt: float) -> None:
        self._battery(dt)
        if not self.armed:
            if not self.landed:  # disarmed in the air: falls
                self.k.vup_mps = max(self.k.vup_mps - 9.81 * dt, -30.0)
                self.k.alt_amsl_m += self.k.vup_mps * dt
                self._touchdown_check()
            return
        if (
            self.landed
            and self._time.t_s - self._armed_at > DISARM_PREFLIGHT_S
            and self.mode not in (TAKEOFF, MISSION)
        ):
            self._announce.statustext(SEV_INFO, "Disarmed by auto preflight disarming")
            self.armed = False
            return
        goal = self._mode_goal()
        if goal is None:
            return
        if self.landed:
            if goal.alt_amsl_m <= self.ground_alt_m + 0.3:
                if self._time.t_s - self._landed_at > DISARM_AFTER_LAND_S and self.mode == LAND:
                    self.armed = False
                    self._announce.statustext(SEV_INFO, "Landing detected, disarmed")
                return
            self.landed = False
            self._announce.statustext(SEV_INFO, "Takeoff detected")
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
            if not self.landed:
                self.landed = True
                self._landed_at = self._time.t_s
                if self.mode == MISSION:
                    self.mission.state = const("MISSION_STATE_COMPLETE")
                    self.mode = LAND  # lands are finished by the land logic (auto-disarm)

    def _battery(self, dt: float) -> None:
        rate = 0.0
        if self.armed:
            rate = 100.0 / self.spec.battery_capacity_s * (1.0 if not self.landed else 0.3)
        self.battery_pct = max(0.0, self.battery_pct - (rate + self._faults.drain_pct_s) * dt)
        level = (
            3
            if self.battery_pct < BAT_EMERG_PCT
            else 2
            if self.battery_pct < BAT_CRIT_PCT
            else 1
            if self.battery_pct < BAT_LOW_PCT
            else 0
        )
        if level > self.bat_level:
            self.bat_level = level
            flying = self.armed and not self.landed
            if level == 1:
                self._announce.statustext(SEV_WARNING, "Low battery level! Return advised")
            elif level == 2:
                self._announce.statustext(SEV_CRITICAL, "Critical battery level! Executing RTL")
                if flying and self.mode not in (LAND, RTL):
                    self.enter_mode(RTL)
            else:
                self._announce.statustext(
                    SEV_EMERGENCY, "Emergency battery level! Landing immediately"
                )
                if flying and self.mode != LAND:
                    self.enter_mode(LAND)

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
        mode = self.mode
        if mode in (HOLD, POSCTL, GUIDED):
            return self._goal(self.goal_ne[0], self.goal_ne[1], self.goal_alt, stop=True)
        if mode == TAKEOFF:
            return self._takeoff_goal()
        if mode in (LOITER, LAND):
            return self._descent_goal(mode)
        if mode == RTL:
            return self._rtl_goal()
        if mode == MISSION:
            return self._mission_goal()
        return None

    def _takeoff_goal(self) -> Goal | None:
        alt = self.takeoff_alt_m
        if self.k.alt_amsl_m >= alt - 0.5:
            self.enter_mode(GUIDED if self.is_ardupilot else HOLD)
            self._announce.statustext(SEV_INFO, "Takeoff complete")
            return self._mode_goal()
        if self.is_fixed_wing:
            # climb out straight ahead, far target along the heading
            n = self.k.north_m + 1000.0 * math.cos(self.k.yaw_rad)
            e = self.k.east_m + 1000.0 * math.sin(self.k.yaw_rad)
            return self._goal(n, e, alt + 1.0, stop=False)
        return self._goal(self.goal_ne[0], self.goal_ne[1], alt + 0.6, stop=True)

    def _descent_goal(self, mode: str) -> Goal:
        """LAND, or ArduCopter's LOITER at minimum RC throttle (straight down)."""
        if mode == LOITER:
            return self._goal(
                self.goal_ne[0],
                self.goal_ne[1],
                self.ground_alt_m - 1.0,
                stop=True,
                descent=self.lim.descent_rate_mps,
            )
        descent = self.lim.descent_rate_mps * (1.7 if self._faults.motor_failed else 1.0)
        speed = self.lim.min_airspeed_mps if self.is_fixed_wing else self._speed()
        return self._goal(
            self.goal_ne[0],
            self.goal_ne[1],
            self.ground_alt_m - 1.0,
            stop=True,
            speed=speed,
            descent=descent,
        )

    def _rtl_goal(self) -> Goal:
        rtl_alt = max(self.k.alt_amsl_m, self.ground_alt_m + self.rtl_alt_rel_m)
        if self.rtl_phase == 0:
            self._rtl_alt = rtl_alt
            self.rtl_phase = 1
        if self.rtl_phase == 1:
            if self.k.alt_amsl_m < self._rtl_alt - 1.0 and not self.is_fixed_wing:
                return self._goal(self.k.north_m, self.k.east_m, self._rtl_alt, stop=True)
            self.rtl_phase = 2
        hn, he = self.frame.to_ne(self.home[0], self.home[1])  # (DO_SET_HOME moves it)
        dist = math.hypot(self.k.north_m - hn, self.k.east_m - he)
        if self.is_fixed_wing:
            return self._goal(hn, he, self._rtl_alt, stop=True)  # loiter over home
        if self.rtl_phase == 2 and dist > 1.0:
            return self._goal(hn, he, self._rtl_alt, stop=True)
        self.rtl_phase = 3
        return self._goal(hn, he, self.ground_alt_m - 1.0, stop=True)

    def _mission_goal(self) -> Goal:
        items = self.mission.items
        first = 1 if self.is_ardupilot else 0
        if self.mission.state == const("MISSION_STATE_COMPLETE") or self.mission.stalled:
            return self._goal(self.goal_ne[0], self.goal_ne[1], self.goal_alt, stop=True)
        self.mission.run_do_items()
        if self.mission.seq >= len(items) or self.mission.seq < first:
            self.mission.seq = max(first, min(self.mission.seq, len(items) - 1))
            self.mission.state = const("MISSION_STATE_COMPLETE")
            return self._goal(self.goal_ne[0], self.goal_ne[1], self.goal_alt, stop=True)
        it = items[self.mission.seq]
        n, e, alt = self.mission.item_target(it)
        if it.command == mp.CMD_TAKEOFF:
            n, e = self.k.north_m, self.k.east_m
            if not math.isfinite(it.z):
                alt = self.ground_alt_m + self.takeoff_alt_rel_m
        special = self._special_goal(it, n, e, alt)
        if special is not None:
            return special
        self.goal_ne, self.goal_alt = (n, e), alt
        last_nav = self.mission.next_nav(self.mission.seq) is None
        hold_s = it.param1 if it.command in (mp.CMD_WAYPOINT, mp.CMD_LOITER_TIME) else 0.0
        if self.mission.reached(it, n, e, alt) and self.mission.done_with(hold_s, last_nav):
            return self._goal(n, e, alt, stop=True)  # mission finished: stay on the last point
        stop = last_nav or hold_s > 0 or it.command in (mp.CMD_LOITER_UNLIM, mp.CMD_LOITER_TIME)
        goal = self._goal(n, e, alt, stop=stop)
        if self.is_fixed_wing and it.command == mp.CMD_WAYPOINT and self.mission.reached_at is None:
            # on the way to a waypoint (a hold at it, and a loiter item, circle the point)
            goal.line_from_ne = self.mission.leg_start(n, e)
        return goal

    def _special_goal(self, it: mp.RawItem, n: float, e: float, alt: float) -> Goal | None:
        """The goal of the initial climb, of an RTL item or of a LAND item (else None)."""
        if self.mission.climb:
            climb_alt = max(alt, self.ground_alt_m + self.takeoff_alt_rel_m)
            if self.k.alt_amsl_m < climb_alt - 1.0:
                if self.is_fixed_wing:
                    return self._goal(n, e, climb_alt, stop=False)
                return self._goal(self.k.north_m, self.k.east_m, climb_alt, stop=True)
            self.mission.climb = False
        if it.command == mp.CMD_RTL:
            self.enter_mode(RTL)
            return self._rtl_goal()
        if it.command == mp.CMD_LAND:
            dist = math.hypot(n - self.k.north_m, e - self.k.east_m)
            if dist > self.mission.acceptance(it) and not self.is_fixed_wing:
                return self._goal(n, e, self.k.alt_amsl_m, stop=True)
            return self._goal(
                n, e, self.ground_alt_m - 1.0, stop=True, descent=self.lim.descent_rate_mps
            )
        return None

    def arm(self, *, force: bool = False) -> int:
        if self.armed:
            return R_ACCEPTED
        if not force:
            if self._faults.motor_failed:
                self._announce.statustext(SEV_CRITICAL, "Preflight Fail: motor failure")
                return R_DENIED
            if self._faults.gps_fix_type() < 3:
                self._announce.statustext(SEV_CRITICAL, "Preflight Fail: GPS fix too low")
                return R_DENIED
            if self.battery_pct < BAT_EMERG_PCT:
                self._announce.statustext(SEV_CRITICAL, "Preflight Fail: battery unhealthy")
                return R_DENIED
            if self._land_start_without_autoland():
                self._announce.statustext(
                    SEV_CRITICAL, "Arm: DO_LAND_START set and RTL_AUTOLAND disabled"
                )
                return R_FAILED
        self.armed = True
        self._armed_at = self._time.t_s
        if not self.home_manual:  # PX4 and ArduPilot take home where they arm (not a set one)
            self.set_home(self.lat_deg, self.lon_deg, self.k.alt_amsl_m)
        self._announce.statustext(SEV_INFO, "Armed by external command")
        return R_ACCEPTED

    def _land_start_without_autoland(self) -> bool:
        """ArduPlane 4.6 refuses to arm with a DO_LAND_START in its mission while
        RTL_AUTOLAND is 0 (measured on the real SITL: COMMAND_ACK 4)."""
        if not (self.is_ardupilot and self.is_fixed_wing):
            return False
        if self.params.get("RTL_AUTOLAND", 0.0) != 0.0:
            return False
        return any(it.command == mp.CMD_LAND_START for it in self.mission.items)

    def disarm(self) -> None:
        if self.armed:
            self.armed = False
            self._announce.statustext(
                SEV_INFO, "Disarmed by external command" if not self.landed else "Disarmed"
            )
