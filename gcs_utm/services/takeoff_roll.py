"""When a fixed wing's take-off run starts (pure; docs/autopilots.md, "Vehicle state").

A plane armed on its runway in a mission mode is re-timed when its mission starts; but the
run need not start then. Measured on PX4 v1.15.2 SIH: armed in mission mode it runs its
mission at once (rolling 0.5 s after the arming; a MISSION_START 6 s later changed nothing),
armed in Hold it stands until MISSION_START; in the short nuisance soak (speed 3, a loaded
machine) the plan was timed from the arming while the plane stood 9 simulated s until the
pilot's MISSION_START, and had it rolling and climbing (UAS_IN_CV 10.9-12.2 m on its
take-off). The run is what the take-off model times, so the plan is re-timed once more when
the plane has left where it armed by :data:`ROLL_START_M` (its run started): from then on it
is where the model has it.

The heading it stands on (where a runway take-off rolls, :mod:`.fixed_wing_runway`) is the
course it last rolled on while armed, when it has rolled since its boot: a parked PX4's yaw
estimate drifts (the 30-minute soak's SIH plane reported 114.6 deg as it armed for its fifth
take-off, standing on 151 deg after its landing's roll-out, and rolled along 151: the plan
from 114.6 was 16.8 m beside it, UAS_IN_CV 22.8 m). Its reported heading before it ever
rolled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs_utm.model import Position

ROLL_START_M = 5.0
"""A plane this far from where it armed has started its take-off run (a standing PX4 SIH
plane's reported position wandered up to 3.4 m while its estimator settled); its course is
sampled over this distance too."""


@dataclass(slots=True)
class RollWatch:
    """One vehicle's watch: armed on the ground (seen disarmed before, not found flying by a
    restarted service), where it stood, until its run starts."""

    disarmed_seen: bool = False
    stood_at: Position | None = None
    moved_from: Position | None = None  # where its last course sample starts (armed)
    rolled_deg: float | None = None  # the course it last moved on, armed

    def update(self, armed: bool, was_armed: bool, position: Position | None) -> None:
        """Take one status (``was_armed``: as the previous status said)."""
        if not armed:
            self.disarmed_seen, self.stood_at, self.moved_from = True, None, None
            return  # (a disarmed plane stands: its reported position wanders)
        if not was_armed and self.disarmed_seen:
            self.stood_at = position
        if position is None:
            return
        if self.moved_from is None:
            self.moved_from = position
        elif _apart_m(self.moved_from, position) >= ROLL_START_M:
            self.rolled_deg = _bearing_deg(self.moved_from, position)
            self.moved_from = position

    def parked_heading_deg(self, reported_deg: float | None) -> float | None:
        """The heading it stands on: the course it last rolled on, else ``reported_deg``."""
        return self.rolled_deg if self.rolled_deg is not None else reported_deg

    def rolled(self, position: Position | None) -> bool:
        """True once, when ``position`` is :data:`ROLL_START_M` from where it armed (the
        watch ends there)."""
        at = self.stood_at
        if at is None or position is None or _apart_m(at, position) < ROLL_START_M:
            return False
        self.stood_at = None
        return True


def _east_north_m(a: Position, b: Position) -> tuple[float, float]:
    k = math.cos(math.radians(a.lat_deg))
    return (b.lon_deg - a.lon_deg) * 111_320.0 * k, (b.lat_deg - a.lat_deg) * 110_540.0


def _apart_m(a: Position, b: Position) -> float:
    return math.hypot(*_east_north_m(a, b))


def _bearing_deg(a: Position, b: Position) -> float:
    return math.degrees(math.atan2(*_east_north_m(a, b))) % 360.0
