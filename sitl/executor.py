"""Mission execution of a simulated vehicle: the mission it holds (as the autopilot stores
it), the current item and the mission state, DO items, when an item counts as reached
(acceptance radius, fixed-wing turn anticipation and finish line, hold time), and the leg a
fixed wing tracks.

:class:`MissionExecutor` is given the vehicle's kinematic state and position frame (read
only) and tells the ground through an :class:`sitl.core.Announcer`; the flight
(:class:`sitl.flight.Flight`) asks it for the current item's target and progress, and keeps
the modes and the goals."""

from __future__ import annotations

import math

from sitl import mission as mp
from sitl._mav import const
from sitl.core import SEV_INFO, SEV_WARNING, Announcer, Timeline, mission_items_from_specs
from sitl.physics import KinState, LocalTangent, l1_distance_m, turn_radius_m
from sitl.spec import ARDUPILOT, FIXED_WING, VehicleSpec


class MissionExecutor:
    """The mission and its progress (see the module docstring)."""

    def __init__(
        self,
        *,
        spec: VehicleSpec,
        time: Timeline,
        k: KinState,
        frame: LocalTangent,
        announce: Announcer,
    ) -> None:
        self._time = time
        self._k = k
        self._frame = frame
        self._announce = announce
        self.is_ardupilot = spec.autopilot == ARDUPILOT
        self.is_fixed_wing = spec.kind == FIXED_WING
        self.lim = spec.limits()
        self.home = (spec.home_lat_deg, spec.home_lon_deg, spec.home_alt_amsl_m)
        # the mission the vehicle boots with (ArduPilot: item 0 is home, current item 1)
        self.items: list[mp.RawItem] = mission_items_from_specs(
            spec.mission, ardupilot=self.is_ardupilot, home=self.home, fixed_wing=self.is_fixed_wing
        )
        self.seq = 1 if self.is_ardupilot and self.items else 0
        self.state = (
            const("MISSION_STATE_NOT_STARTED") if self.items else const("MISSION_STATE_NO_MISSION")
        )
        self.reached_at: float | None = None  # simulated s the current item was reached
        self.stalled = False  # ArduPilot: a replaced mission's current item failed to restart
        self.climb = False  # the initial climb of a mission started on the ground
        self.speed: float | None = None  # set by the mission's DO_CHANGE_SPEED items
        # Fixed wing: where the current mission leg starts (north, east); None until the
        # leg's first goal, which then starts it at the aircraft (a new current item, a new
        # mission).
        self.leg_from_ne: tuple[float, float] | None = None
        # DO_JUMP: item index -> jumps made (PX4's do_jump_current_count, ArduPilot's jump
        # tracking), reset by a new mission and by a reboot
        self.jumps_done: dict[int, int] = {}

    @property
    def first_seq(self) -> int:
        """The first item a mission runs (ArduPilot: 1, item 0 is home)."""
        return 1 if self.is_ardupilot else 0

    def accept(self, items: list[mp.RawItem], flagged_current: int | None, *, flying: bool) -> bool:
        """Store an uploaded mission (as the autopilot keeps it) and choose its current item;
        ``flying``: the vehicle is flying the mission now. True when ArduPilot failed to
        restart the current item: the vehicle then holds where it is."""
        old_seq = self.seq
        if self.is_ardupilot:
            items = [mp.ardupilot_stored(it, fixed_wing=self.is_fixed_wing) for it in items]
            flagged_current = None  # ArduPilot ignores the current flag of an upload
        else:
            items = [mp.px4_stored(it) for it in items]
        self.items = items
        self.jumps_done = {}
        first = self.first_seq
        self.stalled = False
        if flagged_current is not None:
            self.seq = max(first, flagged_current)
        elif flying:
            # PX4 keeps the current index; ArduPilot restarts the command at the same index,
            # which fails on a DO item: the vehicle then holds until told another item
            self.seq = min(old_seq, len(items) - 1)
            if self.is_ardupilot and items[self.seq].command not in mp.NAV_COMMANDS:
                self.stalled = True  # it stops where it is and hovers
                self._announce.statustext(
                    SEV_WARNING, "Auto mission changed but failed to restart command"
                )
            elif self.is_ardupilot:
                self._announce.statustext(SEV_INFO, "Auto mission changed, restarted command")
        else:
            self.seq = first
        self.seq = max(0, min(self.seq, len(items) - 1))
        self.reached_at = None
        self.leg_from_ne = None
        self.state = const("MISSION_STATE_ACTIVE") if flying else const("MISSION_STATE_NOT_STARTED")
        self._announce.mission_current_changed()
        return self.stalled

    def clear(self) -> None:
        self.items = []
        self.jumps_done = {}
        self.seq = 0
        self.state = const("MISSION_STATE_NO_MISSION")

    def reboot(self) -> None:
        """A reboot keeps the stored mission (PX4's dataman, ArduPilot's storage) and starts
        it over: first item, no jumps made, not started."""
        self.jumps_done = {}
        self.seq = self.first_seq if self.items else 0
        self.state = (
            const("MISSION_STATE_NOT_STARTED") if self.items else const("MISSION_STATE_NO_MISSION")
        )
        self.reached_at = None
        self.leg_from_ne = None
        self.stalled = False
        self.climb = False
        self.speed = None

    def start(self, *, on_ground: bool) -> None:
        """The vehicle enters mission mode (from the ground: it climbs first)."""
        if self.is_ardupilot and self.seq == 0:
            self.seq = 1 if len(self.items) > 1 else 0
        self.state = const("MISSION_STATE_ACTIVE")
        self.reached_at = None
        self.leg_from_ne = None
        self.climb = on_ground

    def pause(self) -> None:
        """The vehicle leaves mission mode."""
        if self.items:
            self.state = const("MISSION_STATE_PAUSED")

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

    def wire_items(self) -> list[mp.RawItem]:
        """The mission as a download returns it (ArduPilot: item 0 reads back as home)."""
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

    def set_current(self, seq: int) -> bool:
        """Make ``seq`` the current item (False: no such item)."""
        if not 0 <= seq < len(self.items) or (self.is_ardupilot and seq == 0):
            return False
        self.seq = seq
        self.reached_at = None
        self.leg_from_ne = None
        self.stalled = False
        self._announce.mission_current_changed()
        return True

    def item_target(self, it: mp.RawItem) -> tuple[float, float, float]:
        if it.x == 0 and it.y == 0:
            n, e = self._k.north_m, self._k.east_m
        else:
            n, e = self._frame.to_ne(it.lat_deg, it.lon_deg)
        alt = it.z if math.isfinite(it.z) else self._k.alt_amsl_m
        if it.frame in mp.RELATIVE_FRAMES:
            alt += self.home[2]
        return n, e, alt

    def leg_start(self, n: float, e: float) -> tuple[float, float]:
        """Start of the line a fixed wing tracks to the point (n, e): the previous mission
        point, or where the aircraft was when the item became current. As ArduPlane
        (set_next_WP), an aircraft already past the line's finish starts it where it is."""
        here = (self._k.north_m, self._k.east_m)
        frm = self.leg_from_ne
        if frm is None or _past_finish(frm, (n, e), here):
            frm = here
        self.leg_from_ne = frm
        return frm

    def run_do_items(self) -> None:
        """Execute DO items from the current index up to the next navigation item; a
        DO_JUMP goes to its target while it has repeats left (:meth:`jump_target`)."""
        items = self.items
        guard = 0
        while (
            self.seq < len(items)
            and items[self.seq].command not in mp.NAV_COMMANDS
            and guard < len(items)
        ):
            it = items[self.seq]
            self.speed = self.speed_item(it) or self.speed
            target = self.jump_target(self.seq, self.jumps_done)
            if target is None:
                self.seq += 1
            else:
                self.jumps_done[self.seq] = self.jumps_done.get(self.seq, 0) + 1
                self.seq = target
            guard += 1
            self._announce.mission_current_changed()

    def jump_target(self, seq: int, jumps_done: dict[int, int]) -> int | None:
        """Where the DO_JUMP at ``seq`` goes now, None when it is not a DO_JUMP, its repeats
        are used up or its target is not an item. As PX4 (a jump while
        do_jump_current_count < repeat count) and ArduPilot (jump_times_run < num_times; a
        negative count repeats for ever): a repeat count n flies the loop n + 1 times."""
        it = self.items[seq]
        if it.command != mp.CMD_DO_JUMP:
            return None
        target, repeats = int(it.param1), int(it.param2)
        if not self.first_seq <= target < len(self.items) or target == seq:
            return None
        if 0 <= repeats <= jumps_done.get(seq, 0):
            return None
        return target

    def next_nav(self, seq: int) -> int | None:
        """The navigation item the mission flies after the one at ``seq`` (following the
        DO_JUMPs with the repeats they have left), None when the mission ends there."""
        done = dict(self.jumps_done)
        i = seq + 1
        for _ in range(2 * len(self.items) + 2):
            if i >= len(self.items):
                return None
            if self.items[i].command in mp.NAV_COMMANDS:
                return i
            target = self.jump_target(i, done)
            if target is None:
                i += 1
            else:
                done[i] = done.get(i, 0) + 1
                i = target
        return None

    def reached(self, it: mp.RawItem, n: float, e: float, alt: float) -> bool:
        if it.command == mp.CMD_LOITER_UNLIM:
            return False
        if it.command == mp.CMD_TAKEOFF:
            return self._k.alt_amsl_m >= alt - 1.0
        dist = math.hypot(n - self._k.north_m, e - self._k.east_m)
        if self.is_fixed_wing:
            return abs(alt - self._k.alt_amsl_m) <= 10.0 and self._fixed_wing_reached(
                it, n, e, dist
            )
        return dist <= self.acceptance(it) and abs(alt - self._k.alt_amsl_m) <= 1.5

    def _fixed_wing_reached(self, it: mp.RawItem, n: float, e: float, dist: float) -> bool:
        """A fixed wing is done with a waypoint when it is within the acceptance radius or the
        distance at which the turn onto the next leg begins (its turn radius times
        tan(turn / 2), at most the look-ahead distance: PX4 and ArduPlane both switch early
        so that the turn ends on the next line), or when it has passed the waypoint's finish
        line (ArduPlane's "Passed waypoint"; an overshoot never makes it circle back)."""
        frm = self.leg_from_ne
        if frm is not None and _past_finish(frm, (n, e), (self._k.north_m, self._k.east_m)):
            return True
        turn = self._next_turn_rad(n, e)
        v = max(self._k.airspeed_mps, self.lim.min_airspeed_mps)
        anticipate = min(
            turn_radius_m(v, self.lim) * math.tan(min(turn, math.radians(150.0)) / 2.0),
            l1_distance_m(v),
        )
        return dist <= max(self.acceptance(it), anticipate)

    def _next_turn_rad(self, n: float, e: float) -> float:
        """Course change at the point (n, e) from the current leg onto the next one (0 when
        the mission ends there or the leg has no start yet)."""
        frm = self.leg_from_ne
        nxt = next((x for x in self.items[self.seq + 1 :] if x.command == mp.CMD_WAYPOINT), None)
        if frm is None or nxt is None:
            return 0.0
        n2, e2, _ = self.item_target(nxt)
        a = math.atan2(e - frm[1], n - frm[0])
        b = math.atan2(e2 - e, n2 - n)
        if math.hypot(n - frm[0], e - frm[1]) < 1.0 or math.hypot(n2 - n, e2 - e) < 1.0:
            return 0.0
        return abs((b - a + math.pi) % (2.0 * math.pi) - math.pi)

    def done_with(self, hold_s: float, last_nav: bool) -> bool:
        """The current item is reached: after its hold time go on to the next item; True when
        that ends the mission."""
        if self.reached_at is None:
            self.reached_at = self._time.t_s
            self._announce.broadcast("MISSION_ITEM_REACHED", seq=self.seq)
        if self._time.t_s - self.reached_at < max(0.0, hold_s):
            return False
        self.reached_at = None
        if self.is_fixed_wing:
            it = self.items[self.seq]
            n, e, _ = self.item_target(it)
            self.leg_from_ne = (n, e)  # the next leg starts at this point
        if last_nav:
            self.state = const("MISSION_STATE_COMPLETE")
            self.seq = max(self.seq, len(self.items) - 1)
            self._announce.statustext(SEV_INFO, "Mission finished, loitering")
            return True
        self.seq += 1
        self._announce.mission_current_changed()
        return False

    def acceptance(self, it: mp.RawItem) -> float:
        if it.command == mp.CMD_WAYPOINT and it.param2 > 0:
            return it.param2
        return self.lim.acceptance_radius_m


def _past_finish(
    frm: tuple[float, float], to: tuple[float, float], here: tuple[float, float]
) -> bool:
    """Is ``here`` beyond the line through ``to`` perpendicular to the leg ``frm`` -> ``to``?"""
    ln, le = to[0] - frm[0], to[1] - frm[1]
    if ln * ln + le * le < 1e-6:
        return False
    return (here[0] - to[0]) * ln + (here[1] - to[1]) * le > 0.0
