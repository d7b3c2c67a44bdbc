"""The performance envelope of a vehicle: what it can fly.

Tactical Deconfliction proposes only manoeuvres inside it (see docs/resolution.md). It comes
from the operation's description (:func:`implied`) unless one is given
(``gcs_utm.model.Operation.envelope``: a scenario file, or the autopilot's parameters where
the vehicle reports them). Re-exported by :mod:`gcs_utm.model`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


class EnvelopeError(ValueError):
    """An envelope value that cannot describe a vehicle; ``field_name`` says which."""

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(f"performance envelope: {field_name}: {message}")
        self.field_name = field_name


@dataclass(frozen=True, slots=True, kw_only=True)
class PerformanceEnvelope:
    """Vertical rates (m/s), horizontal speed range (m/s), turn radius (m), and whether the
    vehicle can hover (hold in place): a fixed wing cannot slow below its minimum speed nor
    stop."""

    climb_rate_mps: float
    descent_rate_mps: float
    min_speed_mps: float
    max_speed_mps: float
    turn_radius_m: float
    can_hover: bool
    tracking_error_m: float | None = None
    """How far (horizontally) the vehicle flies from a new plan's 4D position: lag at its
    corners (a multirotor slows down, a fixed wing turns on a radius) that its mission's
    speeds never make up. None: the default of its kind (:meth:`tracking_tolerance_m`)."""

    def tracking_tolerance_m(self) -> float:
        """The tracking error TD keeps free around a new plan (see :attr:`tracking_error_m`)."""
        if self.tracking_error_m is not None:
            return self.tracking_error_m
        return MULTIROTOR_TRACKING_ERROR_M if self.can_hover else FIXED_WING_TRACKING_ERROR_M

    vertical_tracking_error_m: float | None = None
    """How far (vertically) the vehicle flies from a new plan's altitude: altitude-hold error
    and the lag of a climb or descent. None: the default of its kind."""

    def vertical_tracking_tolerance_m(self) -> float:
        """The vertical tracking error TD keeps free around a new plan (see
        :attr:`vertical_tracking_error_m`)."""
        if self.vertical_tracking_error_m is not None:
            return self.vertical_tracking_error_m
        if self.can_hover:
            return MULTIROTOR_VERTICAL_TRACKING_ERROR_M
        return FIXED_WING_VERTICAL_TRACKING_ERROR_M

    horizontal_accel_mps2: float | None = None
    """The horizontal acceleration a multirotor brakes and turns with. None: the default
    (:data:`MULTIROTOR_HORIZONTAL_ACCEL_MPS2`)."""

    def stopping_distance_m(self, speed_mps: float) -> float:
        """How far a vehicle that can hover flies on while it brakes from ``speed_mps`` to a
        stop, ``v^2 / (2 a)`` (0 for one that cannot: it turns on its radius instead)."""
        if not self.can_hover:
            return 0.0
        accel = self.horizontal_accel_mps2 or MULTIROTOR_HORIZONTAL_ACCEL_MPS2
        return speed_mps * speed_mps / (2.0 * accel)

    def __post_init__(self) -> None:
        for name in (
            "climb_rate_mps",
            "descent_rate_mps",
            "min_speed_mps",
            "max_speed_mps",
            "turn_radius_m",
        ):
            if not math.isfinite(getattr(self, name)):
                raise EnvelopeError(name, f"must be a finite number, got {getattr(self, name)!r}")
        for name in ("climb_rate_mps", "descent_rate_mps", "max_speed_mps"):
            if getattr(self, name) <= 0.0:
                raise EnvelopeError(name, "must be positive")
        a = self.horizontal_accel_mps2
        if a is not None and not (math.isfinite(a) and a > 0.0):
            raise EnvelopeError("horizontal_accel_mps2", f"must be a positive number, got {a!r}")
        if self.min_speed_mps < 0.0:
            raise EnvelopeError("min_speed_mps", "must be >= 0")
        if self.turn_radius_m < 0.0:
            raise EnvelopeError("turn_radius_m", "must be >= 0")
        if self.min_speed_mps > self.max_speed_mps:
            raise EnvelopeError("min_speed_mps", "is above max_speed_mps")
        for name in ("tracking_error_m", "vertical_tracking_error_m"):
            t = getattr(self, name)
            if t is not None and not (math.isfinite(t) and t >= 0.0):
                raise EnvelopeError(name, f"must be a finite number >= 0, got {t!r}")


MULTIROTOR_DESCENT_RATE_MPS = 1.5
"""PX4's MPC_Z_V_AUTO_DN and ArduCopter's WPNAV_SPEED_DN default to 1.5 m/s."""
FIXED_WING_DESCENT_RATE_MPS = 3.0
"""Well inside PX4's FW_T_SINK_MAX and ArduPlane's TECS_SINK_MAX (5 m/s)."""
MAX_SPEED_FACTOR = 1.2
"""A vehicle described by its cruise speed alone is assumed to fly up to 20 % faster."""
FIXED_WING_MIN_SPEED_FACTOR = 0.7
"""...and a fixed wing no slower than 70 % of its cruise speed (the stall margin)."""
MULTIROTOR_TRACKING_ERROR_M = 5.0
"""Horizontal 4D tracking error of a multirotor on a manoeuvre: time lost at each corner of
a lateral deformation (PX4 and ArduCopter slow down to turn; the simulated vehicle loses
1-2 s at a sharp one) leaves it a few metres behind its plan's position, measured 2-6 m on
the generated encounters."""
FIXED_WING_TRACKING_ERROR_M = 10.0
"""...of a fixed wing: it cuts each corner on its turn radius and lags along the arc."""
MULTIROTOR_VERTICAL_TRACKING_ERROR_M = 2.0
"""Vertical 4D tracking error of a multirotor: PX4's and ArduCopter's altitude controllers
hold within about a metre and reach a new altitude a second or two late at the descent
rate (1.5 m/s)."""
FIXED_WING_VERTICAL_TRACKING_ERROR_M = 5.0
"""...of a fixed wing: TECS trades height for speed in turns and lags a climb."""
MULTIROTOR_HORIZONTAL_ACCEL_MPS2 = 2.5
"""ArduCopter's WPNAV_ACCEL default (PX4's MPC_ACC_HOR is 3 m/s^2): the lower of the two, so
the stopping distance is not underestimated."""
FIXED_WING_TURN_RADIUS_M = 80.0
"""PX4's NAV_LOITER_RAD default, a turn a small fixed wing flies at cruise speed: the radius
(:func:`turn_radius_m`) at ArduPlane's default roll limit (ROLL_LIMIT_DEG 45) at 28 m/s, and
above PX4's (FW_R_LIM 50) at 30 m/s."""
GRAVITY_MPS2 = 9.80665


def turn_radius_m(speed_mps: float, roll_limit_deg: float) -> float:
    """The radius of a coordinated level turn at ``speed_mps`` banked ``roll_limit_deg``:
    ``v^2 / (g tan(roll))`` (ArduPlane ROLL_LIMIT_DEG, PX4 FW_R_LIM)."""
    if not (math.isfinite(speed_mps) and speed_mps >= 0.0):
        raise EnvelopeError("speed_mps", f"must be a finite number >= 0, got {speed_mps!r}")
    if not (math.isfinite(roll_limit_deg) and 0.0 < roll_limit_deg < 90.0):
        raise EnvelopeError("roll_limit_deg", f"must be in (0, 90) degrees, got {roll_limit_deg!r}")
    return speed_mps * speed_mps / (GRAVITY_MPS2 * math.tan(math.radians(roll_limit_deg)))


def implied(
    fixed_wing: bool, cruise_speed_mps: float, climb_rate_mps: float
) -> PerformanceEnvelope:
    """The envelope a description (kind, cruise speed, climb rate) implies; the descent rate
    is never above the climb rate."""
    descent = FIXED_WING_DESCENT_RATE_MPS if fixed_wing else MULTIROTOR_DESCENT_RATE_MPS
    return PerformanceEnvelope(
        climb_rate_mps=climb_rate_mps,
        descent_rate_mps=min(climb_rate_mps, descent),
        min_speed_mps=FIXED_WING_MIN_SPEED_FACTOR * cruise_speed_mps if fixed_wing else 0.0,
        max_speed_mps=MAX_SPEED_FACTOR * cruise_speed_mps,
        turn_radius_m=FIXED_WING_TURN_RADIUS_M if fixed_wing else 0.0,
        can_hover=not fixed_wing,
    )
