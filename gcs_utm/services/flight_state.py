"""Each vehicle's flight state from its own messages, and the one notion of being airborne.

A vehicle is **airborne** when it is armed (HEARTBEAT ``base_mode`` armed flag) and
- it reports a landed state (EXTENDED_SYS_STATE) other than on the ground: in the air, taking
  off or landing; or
- it reports none (``MAV_LANDED_STATE_UNDEFINED``, or no EXTENDED_SYS_STATE): it is more than
  ``airborne_height_m`` above its home, or has moved more than ``airborne_move_m`` from where
  it was armed.
It is **on the ground** (pre-flight) when it says so: disarmed, or armed with the landed
state on the ground. An armed vehicle that reports no landed state and shows neither height
nor movement yet (e.g. heard for the first time) is neither: nothing is assumed either way.

The state machine (transitions returned by :meth:`FlightState.update`):

    PREFLIGHT --armed--> ARMED --airborne--> AIRBORNE --landed/disarmed--> LANDED
    any --time_boot_ms back (reboot)--> PREFLIGHT (a new life: fix, home and arming forgotten)

``fix`` is a 3D GNSS fix (GPS_RAW_INT ``fix_type`` >= 3; from a source that sends no
GPS_RAW_INT, any reported position); until the first one the vehicle's
HOME_POSITION is not its home (PX4 sends one 0.4 s after boot, before its fix). Pure: the USM
feeds it :class:`~gcs_utm.messages.VehicleStatus` and reads it; no I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from gcs_utm.messages import VehicleStatus
from gcs_utm.model import Position

AIRBORNE_HEIGHT_M = 2.0
"""Without a landed state: higher than this above home is in the air (more than the ~1 m a
GNSS/baro altitude of a vehicle standing on the ground wanders)."""
AIRBORNE_MOVE_M = 5.0
"""Without a landed state: further than this from where it was armed is moving (a fixed wing
rolling for take-off, a vehicle carried away while armed is still traffic)."""


class Phase(Enum):
    PREFLIGHT = "preflight"  # on the ground, disarmed
    ARMED = "armed"  # armed, still on the ground
    AIRBORNE = "airborne"
    LANDED = "landed"  # on the ground after a flight (disarmed or landed)


@dataclass(slots=True)
class FlightState:
    """One vehicle (one system id on one link). ``home`` is its HOME_POSITION once it has had a
    3D fix."""

    phase: Phase = Phase.PREFLIGHT
    armed: bool = False
    fix: bool = False  # a 3D fix now
    had_fix: bool = False  # a 3D fix since the last boot
    reboots: int = 0
    home: Position | None = None
    armed_at: Position | None = None  # where it was when it armed

    on_ground: bool = False  # disarmed, or armed and landed by its own landed state

    @property
    def airborne(self) -> bool:
        return self.phase is Phase.AIRBORNE

    @property
    def flying(self) -> bool | None:
        """True airborne, False on the ground, None when its messages do not tell."""
        return True if self.airborne else (False if self.on_ground else None)

    def update(self, s: VehicleStatus) -> list[str]:
        """Take one status; the transitions it made, in order (``rebooted``, ``fix``,
        ``home``, ``armed``, ``took_off``, ``landed``, ``disarmed``)."""
        out: list[str] = []
        if s.reboots != self.reboots:
            self.reboots = s.reboots
            self.phase, self.armed, self.fix, self.had_fix = Phase.PREFLIGHT, False, False, False
            self.home = self.armed_at = None
            out.append("rebooted")
        if s.gnss_fix_type is None:  # no GPS_RAW_INT (another source): once it has positions
            self.fix = s.position is not None
        else:
            self.fix = s.gnss_fix_type >= 3
        if self.fix and not self.had_fix:
            self.had_fix = True
            out.append("fix")
        if self.had_fix and s.home is not None and s.home != self.home:
            self.home = s.home
            out.append("home")
        if s.armed and not self.armed:
            self.armed_at = s.position
            out.append("armed")
        elif self.armed and not s.armed:
            out.append("disarmed")
        self.armed = s.armed
        up = s.armed and self._in_air(s)
        self.on_ground = not up and (not s.armed or s.landed is True)
        if up and self.phase is not Phase.AIRBORNE:
            out.append("took_off")
        elif not up and self.phase is Phase.AIRBORNE:
            out.append("landed")
        if up:
            self.phase = Phase.AIRBORNE
        elif self.phase is Phase.AIRBORNE or (self.phase is Phase.LANDED and not s.armed):
            self.phase = Phase.LANDED
        else:
            self.phase = Phase.ARMED if s.armed else Phase.PREFLIGHT
        return out

    def _in_air(self, s: VehicleStatus) -> bool:
        if s.landed is not None:  # EXTENDED_SYS_STATE: in air, taking off, landing
            return not s.landed
        pos = s.position
        if pos is None:
            return self.phase is Phase.AIRBORNE  # nothing new: as it was
        home = self.home
        if home is not None and pos.alt_amsl_m - home.alt_amsl_m > AIRBORNE_HEIGHT_M:
            return True
        return self.armed_at is not None and _horizontal_m(self.armed_at, pos) > AIRBORNE_MOVE_M


def _horizontal_m(a: Position, b: Position) -> float:
    k = math.cos(math.radians(a.lat_deg))
    return math.hypot((b.lat_deg - a.lat_deg) * 110_540.0, (b.lon_deg - a.lon_deg) * 111_320.0 * k)
