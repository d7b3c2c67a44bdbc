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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs_utm.model import Position

ROLL_START_M = 5.0
"""A plane this far from where it armed has started its take-off run (a standing PX4 SIH
plane's reported position wandered up to 3.4 m while its estimator settled)."""


@dataclass(slots=True)
class RollWatch:
    """One vehicle's watch: armed on the ground (seen disarmed before, not found flying by a
    restarted service), where it stood, until its run starts."""

    disarmed_seen: bool = False
    stood_at: Position | None = None

    def update(self, armed: bool, was_armed: bool, position: Position | None) -> None:
        """Take one status (``was_armed``: as the previous status said)."""
        if not armed:
            self.disarmed_seen, self.stood_at = True, None
        elif not was_armed and self.disarmed_seen:
            self.stood_at = position

    def rolled(self, position: Position | None) -> bool:
        """True once, when ``position`` is :data:`ROLL_START_M` from where it armed (the
        watch ends there)."""
        at = self.stood_at
        if at is None or position is None:
            return False
        k = math.cos(math.radians(at.lat_deg))
        moved_m = math.hypot(
            (position.lat_deg - at.lat_deg) * 110_540.0,
            (position.lon_deg - at.lon_deg) * 111_320.0 * k,
        )
        if moved_m < ROLL_START_M:
            return False
        self.stood_at = None
        return True
