"""PX4's runway take-off from a heading that is not the take-off waypoint's (pure;
docs/autopilots.md, "Fixed wings: take-off, loiters, landing").

PX4 v1.15's runway take-off (``RunwayTakeoff``, RWTO_HDG 0, the default) holds the heading
the plane had when the take-off started (``initial_yaw``) on the ground, wings level, until
the rotation airspeed; from lift-off its guidance steers. A plane parked after a landing
stands on its landing's heading, not its next take-off's. Measured on PX4 v1.15.2 SIH (the
nuisance soak's plane, parked heading 154 deg, take-off waypoint 600 m to the north; two
take-offs): it rolled 18-20 m south-east, lifted off, turned left at its roll limit (50 deg/s,
NPFG's command saturates while the heading error is large) through north to about -40 deg,
then converged slowly on the line from its start to the take-off waypoint (still 10 m east
of it 100 m north of its start), climbing as on a straight take-off; the straight climb-out
from its start put it 33-35 m beside its plan (UAS_OUT_OV, an auto-accepted hold), heading
for the waypoint itself after the turn 26 m.

The model: the ground roll along the parked heading to :data:`LIFT_OFF_M`, then the turn at
the roll limit until it heads for the line's point one NPFG track-error bound past the
lift-off's projection (:func:`.fixed_wing_turn.takeoff_turn` with ``full_bank``), straight to
that point, then along the line; climbing with the distance flown as the straight climb-out
does (level once at the take-off altitude). Across, within 1.6 and 11.9 m of the two
recorded take-offs (the second's overshoot of the turn and slow convergence are not
modelled); up, within 5.6 m during the climb."""

from __future__ import annotations

import math
from typing import TypeVar

from gcs_utm.services.fixed_wing_point import Point
from gcs_utm.services.fixed_wing_turn import (
    PX4_PERIOD_S,
    PX4_ROLL_LIMIT_DEG,
    PX4_TRIM_MPS,
    takeoff_turn,
)

P = TypeVar("P", bound=Point)

ALIGNED_DEG = 10.0
"""A parked heading within this of the bearing to the take-off waypoint is the straight
climb-out (the turn back onto the line would be within the fixed-wing band)."""
NPFG_DAMPING = 0.7
"""PX4's NPFG_DAMPING (default): with NPFG_PERIOD, its track-error bound ``V T damping`` (105 m
at 15 m/s), the distance over which it converges on a line."""
LIFT_OFF_M = 18.0
"""PX4 v1.15.2 SIH's ground roll (about 18 m, the straight take-off's too): where the turn
from a parked heading can start."""
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def runway_from_heading(start: P, heading_deg: float, climb: list[P], wp: P) -> list[P] | None:
    """The take-off to ``wp`` (the NAV_TAKEOFF item with its position) from ``start`` (where
    the plane stands, at the ground's altitude) parked on ``heading_deg``, given ``climb``
    (the straight climb-out's ground-roll end and climb end along the line to ``wp``, as
    :func:`.fixed_wing_plan._climb_out` models it): the points from ``start`` on (module
    docstring); None when the heading is the line's (the straight climb-out holds)."""
    if len(climb) != 2:
        return None
    k = math.cos(math.radians(start.lat_deg))

    def en(q: Point) -> tuple[float, float]:
        return (
            (q.lon_deg - start.lon_deg) * _M_PER_DEG_LON * k,
            (q.lat_deg - start.lat_deg) * _M_PER_DEG_LAT,
        )

    we, wn = en(wp)
    length_m = math.hypot(we, wn)
    if length_m < 1.0 or abs(_wrap_deg(heading_deg - math.degrees(math.atan2(we, wn)))) < (
        ALIGNED_DEG
    ):
        return None
    roll_m = min(LIFT_OFF_M, math.hypot(*en(climb[0])))
    run_m = max(math.hypot(*en(climb[1])), roll_m + 1.0)
    base_m, top_m = climb[0].alt_amsl_m, climb[1].alt_amsl_m
    he, hn = math.sin(math.radians(heading_deg)), math.cos(math.radians(heading_deg))

    def at(e: float, n: float, alt: float) -> P:
        lat = start.lat_deg + n / _M_PER_DEG_LAT
        lon = start.lon_deg + e / (_M_PER_DEG_LON * k)
        return wp.moved(lat, lon, alt).synthetic()

    def climbed(flown_m: float) -> float:
        """The altitude after ``flown_m`` from the start (the straight climb-out's gradient)."""
        frac = min(max((flown_m - roll_m) / (run_m - roll_m), 0.0), 1.0)
        return base_m + (top_m - base_m) * frac

    lift = at(he * roll_m, hn * roll_m, base_m)
    speed = min(max(wp.speed_mps, 1.0), PX4_TRIM_MPS)
    # the line's point one track-error bound past the lift-off's projection
    ue, un = we / length_m, wn / length_m
    s_m = roll_m * (he * ue + hn * un) + NPFG_DAMPING * PX4_PERIOD_S * speed
    s_m = min(max(s_m, 0.0), length_m)
    target = at(ue * s_m, un * s_m, top_m)
    turn = takeoff_turn(lift, heading_deg, target, speed, period_s=PX4_PERIOD_S, roll_in_s=0.0,
                        roll_limit_deg=PX4_ROLL_LIMIT_DEG, full_bank=True)  # fmt: skip
    # where it stands first: a plan from the point of the take-off nearest the plane
    # (vehicle_ops) starts there, not part-way round the turn
    out: list[P] = [at(0.0, 0.0, base_m), lift]
    flown_m, last = roll_m, en(lift)
    for q in [*turn, target]:
        e, n = en(q)
        flown_m += math.hypot(e - last[0], n - last[1])
        last = (e, n)
        out.append(at(e, n, climbed(flown_m)))
    # on along the line: the take-off altitude reached on the way, then level
    left_m = math.hypot(we - last[0], wn - last[1])
    rest_m = run_m - flown_m
    if 1.0 < rest_m < left_m - 1.0:
        f = rest_m / left_m
        out.append(at(last[0] + (we - last[0]) * f, last[1] + (wn - last[1]) * f, top_m))
    return [*out, wp] if left_m >= 1.0 else out
