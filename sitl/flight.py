"""Flight of a simulated vehicle: modes, mission execution (the MissionHost side of
:mod:`sitl.mission`), take-off/landing detection, battery, arming, and one physics step.

:class:`Flight` holds the kinematic state, the mode, the mission and the flight parameters;
it reads the fault state (:class:`sitl.faults.Faults`) and tells the ground through an
:class:`sitl.core.Announcer`. It is the :class:`sitl.faults.FaultTarget` of the faults."""

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
    mission_items_from_specs,
)
from sitl.faults import Faults
from sitl.physics import (
    Goal,
    KinState,
    LocalTangent,
    l1_distance_m,
    step_fixed_wing,
    step_multirotor,
    turn_radius_m,
)
from sitl.spec import ARDUPILOT, FIXED_WING, VehicleSpec

_log = logging.getLogger(__name__)


class Flight:
    """Modes and mission execution (see the module docstring)."""

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
        self.k = KinState(alt_amsl_m=spec.home_alt_amsl_m)
        self.battery_pct = 100.0
        self.bat_level = 0  # 0 ok, 1 low, 2 critical, 3 emergency
        self._auto_started = False
        self._init_flight(spec)
        self._init_mission(spec)
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

    def _init_mission(self, spec: VehicleSpec) -> None:
        """The mission the vehicle boots with (ArduPilot: item 0 is home, current item 1)."""
        self.items: list[mp.RawItem] = mission_items_from_specs(
            spec.mission, ardupilot=self.is_ardupilot, home=self.home, fixed_wing=self.is_fixed_wing
        )
        self.seq = 1 if self.is_ardupilot and self.items else 0
        self.mission_state = (
            const("MISSION_STATE_NOT_STARTED") if self.items else const("MISSION_STATE_NO_MISSION")
        )
        self._item_reached_at: float | None = None
        self._stalled = False  # ArduPilot: a replaced mission's current item failed to restart
        self._mission_climb = False
        self.mission_speed: float | None = None
        # Fixed wing: where the current mission leg starts (north, east); None until the
        # leg's first goal, which then starts it at the aircraft (a new current item, a new
        # mission).
        self._leg_from_ne: tuple[float, float] | None = None

    @property
    def lat_deg(self) -> float:
        return self.frame.to_latlon(self.k.north_m, self.k.east_m)[0]

    @property
    def lon_deg(self) -> float:
        return self.frame.to_latlon(self.k.north_m, self.k.east_m)[1]

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

    # FaultTarget ---------------------------------------------------------------------

    def drop_battery(self, pct: float) -> None:
        self.battery_pct = min(self.battery_pct, pct)

    def land_now(self) -> None:
        if self.armed and not self.landed:
            self.enter_mode(LAND)

    # MissionHost (the mission's side) -------------------------------------------------

    def mission_items(self) -> list[mp.RawItem]:
        if self.is_ardupilot and self.items:
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
            return [home, *self.items[1:]]
        return list(self.items)

    def accept_mission(self, items: list[mp.RawItem], flagged_current: int | None) -> None:
        flying_mission = self.mode == MISSION and self.armed and not self.landed
        old_seq = self.seq
        if self.is_ardupilot:
            items = [mp.ardupilot_stored(it, fixed_wing=self.is_fixed_wing) for it in items]
            flagged_current = None  # ArduPilot ignores the current flag of an upload
        else:
            items = [mp.px4_stored(it) for it in items]
        self.items = items
        first = 1 if self.is_ardupilot else 0
        self._stalled = False
        if flagged_current is not None:
            self.seq = max(first, flagged_current)
        elif flying_mission:
            # PX4 keeps the current index; ArduPilot restarts the command at the same index,
            # which fails on a DO item: the vehicle then holds until told another item
            self.seq = min(old_seq, len(items) - 1)
            if self.is_ardupilot and items[self.seq].command not in mp.NAV_COMMANDS:
                self._stalled = True  # it stops where it is and hovers
                self.goal_ne = (self.k.north_m, self.k.east_m)
                self.goal_alt = self.k.alt_amsl_m
                self._announce.statustext(
                    SEV_WARNING, "Auto mission changed but failed to restart command"
                )
            elif self.is_ardupilot:
                self._announce.statustext(SEV_INFO, "Auto mission changed, restarted command")
        else:
            self.seq = first
        self.seq = max(0, min(self.seq, len(items) - 1))
        self._item_reached_at = None
        self._leg_from_ne = None
        self.mission_state = (
            const("MISSION_STATE_ACTIVE") if flying_mission else const("MISSION_STATE_NOT_STARTED")
        )
        self._announce.mission_current_changed()

    def clear_mission(self) -> None:
        self.items = []
        self.seq = 0
        self.mission_state = const("MISSION_STATE_NO_MISSION")
        if self.mode == MISSION and not self.landed:
            self._enter_hold()
        self._announce.mission_current_changed()

    def set_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self.items) or (self.is_ardupilot and seq == 0):
            return False
        self.seq = seq
        self._item_reached_at = None
        self._leg_from_ne = None
        self._stalled = False
        self._announce.mission_current_changed()
        return True

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
            if self.is_ardupilot and self.seq == 0:
                self.seq = 1 if len(self.items) > 1 else 0
            self.mission_state = const("MISSION_STATE_ACTIVE")
            self._item_reached_at = None
            self._leg_from_ne = None
            self._mission_climb = self.landed
        if target != MISSION and prev == MISSION and self.items:
            self.mission_state = const("MISSION_STATE_PAUSED")
        if prev != target:
            _log.info("sysid %d: mode %s -> %s", self.sys_id, prev, target)

    def auto_start(self) -> None:
        at = self.spec.auto_start_at_s
        if self._auto_started or at is None or self._time.t_s < at:
            return
        self._auto_started = True
        if self.arm() != R_ACCEPTED:
            return
        if self.items and self.spec.start_airborne:
            self._place_airborne()
        if self.items:
            self.enter_mode(MISSION)
        else:
            self.takeoff_alt_m = self.ground_alt_m + self.takeoff_alt_rel_m
            self.enter_mode(TAKEOFF)

    def _place_airborne(self) -> None:
        """Scenario start in flight: put the vehicle at its first mission waypoint, at its
        altitude, already moving towards the next one at the mission speed (see
        VehicleSpec.start_airborne)."""
        items = self.items
        first = 1 if self.is_ardupilot else 0
        navs = [i for i in range(first, len(items)) if items[i].command in mp.NAV_COMMANDS]
        if not navs:
            return
        i0 = navs[0]
        n0, e0, alt0 = self._item_target(items[i0])
        self.k.north_m, self.k.east_m, self.k.alt_amsl_m = n0, e0, alt0
        self.landed = False
        self.seq = i0
        speed = self.cruise_mps
        if len(navs) > 1:
            for it in items[i0 + 1 : navs[1]]:
                speed = self.speed_item(it) or speed
            n1, e1, _alt1 = self._item_target(items[navs[1]])
            dist = math.hypot(n1 - n0, e1 - e0)
            if dist > 0.0:
                speed = min(speed, self.lim.max_speed_mps)
                self.k.yaw_rad = math.atan2(e1 - e0, n1 - n0)
                self.k.vn_mps = speed * (n1 - n0) / dist
                self.k.ve_mps = speed * (e1 - e0) / dist
                self.k.airspeed_mps = speed
        self._announce.statustext(SEV_INFO, "Scenario start in flight")

    def _speed(self) -> float:
        v = self.speed_override or self.mission_speed or self.cruise_mps
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
                    self.mission_state = const("MISSION_STATE_COMPLETE")
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
        dist = math.hypot(self.k.north_m, self.k.east_m)
        if self.is_fixed_wing:
            return self._goal(0.0, 0.0, self._rtl_alt, stop=True)  # loiter over home
        if self.rtl_phase == 2 and dist > 1.0:
            return self._goal(0.0, 0.0, self._rtl_alt, stop=True)
        self.rtl_phase = 3
        return self._goal(0.0, 0.0, self.ground_alt_m - 1.0, stop=True)

    def _item_target(self, it: mp.RawItem) -> tuple[float, float, float]:
        if it.x == 0 and it.y == 0:
            n, e = self.k.north_m, self.k.east_m
        else:
            n, e = self.frame.to_ne(it.lat_deg, it.lon_deg)
        alt = it.z if math.isfinite(it.z) else self.k.alt_amsl_m
        if it.frame in mp.RELATIVE_FRAMES:
            alt += self.home[2]
        return n, e, alt

    def _mission_goal(self) -> Goal:
        items = self.items
        first = 1 if self.is_ardupilot else 0
        if self.mission_state == const("MISSION_STATE_COMPLETE") or self._stalled:
            return self._goal(self.goal_ne[0], self.goal_ne[1], self.goal_alt, stop=True)
        self._run_do_items()
        if self.seq >= len(items) or self.seq < first:
            self.seq = max(first, min(self.seq, len(items) - 1))
            self.mission_state = const("MISSION_STATE_COMPLETE")
            return self._goal(self.goal_ne[0], self.goal_ne[1], self.goal_alt, stop=True)
        it = items[self.seq]
        n, e, alt = self._item_target(it)
        if it.command == mp.CMD_TAKEOFF:
            n, e = self.k.north_m, self.k.east_m
            if not math.isfinite(it.z):
                alt = self.ground_alt_m + self.takeoff_alt_rel_m
        special = self._special_goal(it, n, e, alt)
        if special is not None:
            return special
        self.goal_ne, self.goal_alt = (n, e), alt
        last_nav = not any(x.command in mp.NAV_COMMANDS for x in items[self.seq + 1 :])
        hold_s = it.param1 if it.command in (mp.CMD_WAYPOINT, mp.CMD_LOITER_TIME) else 0.0
        if self._reached(it, n, e, alt) and self._done_with(hold_s, last_nav):
            return self._goal(n, e, alt, stop=True)  # mission finished: stay on the last point
        stop = last_nav or hold_s > 0 or it.command in (mp.CMD_LOITER_UNLIM, mp.CMD_LOITER_TIME)
        goal = self._goal(n, e, alt, stop=stop)
        if self.is_fixed_wing and it.command == mp.CMD_WAYPOINT and self._item_reached_at is None:
            # on the way to a waypoint (a hold at it, and a loiter item, circle the point)
            goal.line_from_ne = self._leg_start(n, e)
        return goal

    def _leg_start(self, n: float, e: float) -> tuple[float, float]:
        """Start of the line a fixed wing tracks to the point (n, e): the previous mission
        point, or where the aircraft was when the item became current. As ArduPlane
        (set_next_WP), an aircraft already past the line's finish starts it where it is."""
        here = (self.k.north_m, self.k.east_m)
        frm = self._leg_from_ne
        if frm is None or _past_finish(frm, (n, e), here):
            frm = here
        self._leg_from_ne = frm
        return frm

    def _run_do_items(self) -> None:
        """Execute DO items from the current index up to the next navigation item."""
        items = self.items
        guard = 0
        while (
            self.seq < len(items)
            and items[self.seq].command not in mp.NAV_COMMANDS
            and guard < len(items)
        ):
            it = items[self.seq]
            self.mission_speed = self.speed_item(it) or self.mission_speed
            self.seq += 1
            guard += 1
            self._announce.mission_current_changed()

    def _special_goal(self, it: mp.RawItem, n: float, e: float, alt: float) -> Goal | None:
        """The goal of the initial climb, of an RTL item or of a LAND item (else None)."""
        if self._mission_climb:
            climb_alt = max(alt, self.ground_alt_m + self.takeoff_alt_rel_m)
            if self.k.alt_amsl_m < climb_alt - 1.0:
                if self.is_fixed_wing:
                    return self._goal(n, e, climb_alt, stop=False)
                return self._goal(self.k.north_m, self.k.east_m, climb_alt, stop=True)
            self._mission_climb = False
        if it.command == mp.CMD_RTL:
            self.enter_mode(RTL)
            return self._rtl_goal()
        if it.command == mp.CMD_LAND:
            dist = math.hypot(n - self.k.north_m, e - self.k.east_m)
            if dist > self._acceptance(it) and not self.is_fixed_wing:
                return self._goal(n, e, self.k.alt_amsl_m, stop=True)
            return self._goal(
                n, e, self.ground_alt_m - 1.0, stop=True, descent=self.lim.descent_rate_mps
            )
        return None

    def _reached(self, it: mp.RawItem, n: float, e: float, alt: float) -> bool:
        if it.command == mp.CMD_LOITER_UNLIM:
            return False
        if it.command == mp.CMD_TAKEOFF:
            return self.k.alt_amsl_m >= alt - 1.0
        dist = math.hypot(n - self.k.north_m, e - self.k.east_m)
        if self.is_fixed_wing:
            return abs(alt - self.k.alt_amsl_m) <= 10.0 and self._fixed_wing_reached(it, n, e, dist)
        return dist <= self._acceptance(it) and abs(alt - self.k.alt_amsl_m) <= 1.5

    def _fixed_wing_reached(self, it: mp.RawItem, n: float, e: float, dist: float) -> bool:
        """A fixed wing is done with a waypoint when it is within the acceptance radius or the
        distance at which the turn onto the next leg begins (its turn radius times
        tan(turn / 2), at most the look-ahead distance: PX4 and ArduPlane both switch early
        so that the turn ends on the next line), or when it has passed the waypoint's finish
        line (ArduPlane's "Passed waypoint"; an overshoot never makes it circle back)."""
        frm = self._leg_from_ne
        if frm is not None and _past_finish(frm, (n, e), (self.k.north_m, self.k.east_m)):
            return True
        turn = self._next_turn_rad(n, e)
        v = max(self.k.airspeed_mps, self.lim.min_airspeed_mps)
        anticipate = min(
            turn_radius_m(v, self.lim) * math.tan(min(turn, math.radians(150.0)) / 2.0),
            l1_distance_m(v),
        )
        return dist <= max(self._acceptance(it), anticipate)

    def _next_turn_rad(self, n: float, e: float) -> float:
        """Course change at the point (n, e) from the current leg onto the next one (0 when
        the mission ends there or the leg has no start yet)."""
        frm = self._leg_from_ne
        nxt = next((x for x in self.items[self.seq + 1 :] if x.command == mp.CMD_WAYPOINT), None)
        if frm is None or nxt is None:
            return 0.0
        n2, e2, _ = self._item_target(nxt)
        a = math.atan2(e - frm[1], n - frm[0])
        b = math.atan2(e2 - e, n2 - n)
        if math.hypot(n - frm[0], e - frm[1]) < 1.0 or math.hypot(n2 - n, e2 - e) < 1.0:
            return 0.0
        return abs((b - a + math.pi) % (2.0 * math.pi) - math.pi)

    def _done_with(self, hold_s: float, last_nav: bool) -> bool:
        """The current item is reached: after its hold time go on to the next item; True when
        that ends the mission."""
        if self._item_reached_at is None:
            self._item_reached_at = self._time.t_s
            self._announce.broadcast("MISSION_ITEM_REACHED", seq=self.seq)
        if self._time.t_s - self._item_reached_at < max(0.0, hold_s):
            return False
        self._item_reached_at = None
        if self.is_fixed_wing:
            it = self.items[self.seq]
            n, e, _ = self._item_target(it)
            self._leg_from_ne = (n, e)  # the next leg starts at this point
        if last_nav:
            self.mission_state = const("MISSION_STATE_COMPLETE")
            self.seq = max(self.seq, len(self.items) - 1)
            self._announce.statustext(SEV_INFO, "Mission finished, loitering")
            return True
        self.seq += 1
        self._announce.mission_current_changed()
        return False

    def _acceptance(self, it: mp.RawItem) -> float:
        if it.command == mp.CMD_WAYPOINT and it.param2 > 0:
            return it.param2
        return self.lim.acceptance_radius_m

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
        self._announce.statustext(SEV_INFO, "Armed by external command")
        return R_ACCEPTED

    def _land_start_without_autoland(self) -> bool:
        """ArduPlane 4.6 refuses to arm with a DO_LAND_START in its mission while
        RTL_AUTOLAND is 0 (measured on the real SITL: COMMAND_ACK 4)."""
        if not (self.is_ardupilot and self.is_fixed_wing):
            return False
        if self.params.get("RTL_AUTOLAND", 0.0) != 0.0:
            return False
        return any(it.command == mp.CMD_LAND_START for it in self.items)

    def disarm(self) -> None:
        if self.armed:
            self.armed = False
            self._announce.statustext(
                SEV_INFO, "Disarmed by external command" if not self.landed else "Disarmed"
            )


def _past_finish(
    frm: tuple[float, float], to: tuple[float, float], here: tuple[float, float]
) -> bool:
    """Is ``here`` beyond the line through ``to`` perpendicular to the leg ``frm`` -> ``to``?"""
    ln, le = to[0] - frm[0], to[1] - frm[1]
    if ln * ln + le * le < 1e-6:
        return False
    return (here[0] - to[0]) * ln + (here[1] - to[1]) * le > 0.0
