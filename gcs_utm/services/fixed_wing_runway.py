"""PX4's runway take-off from a heading that is not the take-off waypoint's (pure;
docs/autopilots.md, "Fixed wings: take-off, loiters, landing").

PX4 v1.15's runway take-off (``RunwayTakeoff``, RWTO_HDG 0, the default) holds the heading
the plane had when the take-off started (``initial_yaw``) on the ground, wings level, until
the rotation airspeed (THROTTLE_RAMP, CLAMPED_TO_RUNWAY); from lift-off (CLIMBOUT) its
guidance tracks the line from where the take-off started towards the take-off waypoint
(``navigateLine(start, bearing)``) while it climbs. A plane parked after a landing stands on
its landing's heading, not its next take-off's: the soak's PX4 SIH plane, heading 157 deg
for a take-off waypoint to the north, rolled and lifted off south-east, then turned back at
its roll limit (NPFG's command saturates while the heading error is large) onto the line;
the straight climb-out along that line put it 34-35 m beside its plan (UAS_OUT_OV).

The model: the ground roll along the parked heading, then the turn at the roll limit towards
the line's point one guidance distance past the lift-off's projection
(:func:`.fixed_wing_turn.takeoff_turn` with ``full_bank``), climbing as the straight climb-out
does with the distance flown, then on along the line until the take-off altitude, then level
to the take-off waypoint."""

from __future__ import annotations

import math
from typing import TypeVar

from gcs_utm.services.fixed_wing_point import Point
from gcs_utm.services.fixed_wing_turn import (
    L1_DAMPING,
    PX4_PERIOD_S,
    PX4_ROLL_LIMIT_DEG,
    PX4_TRIM_MPS,
    takeoff_turn,
)

P = TypeVar("P", bound=Point)

ALIGNED_DEG = 10.0
"""A parked heading within this of the bearing to the take-off waypoint is the straight
climb-out (the turn back onto the line would be within the fixed-wing band)."""
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def runway_from_heading(start: P, heading_deg: float, climb: list[P], wp: P) -> list[P] | None:
    """The take-off to ``wp`` (the NAV_TAKEOFF item with its position) from ``start`` (where
    the plane stands, at the ground's altitude) parked on ``heading_deg``, given ``climb``
    (the straight climb-out's ground-roll end and climb end along the line to ``wp``, as
    :func:`.fixed_wing_plan._climb_out` models it): the points after ``start`` (module
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
    ue, un = we / length_m, wn / length_m
    roll_m = math.hypot(*en(climb[0]))
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
    s_m = roll_m * (he * ue + hn * un) + L1_DAMPING * PX4_PERIOD_S * speed / math.pi
    s_m = min(max(s_m, 0.0), length_m)
    target = at(ue * s_m, un * s_m, top_m)
    turn = takeoff_turn(lift, heading_deg, target, speed, period_s=PX4_PERIOD_S, roll_in_s=0.0,
                        roll_limit_deg=PX4_ROLL_LIMIT_DEG, full_bank=True)  # fmt: skip
    out: list[P] = [lift]
    flown_m, last = roll_m, en(lift)
    for q in [*turn, target]:
        e, n = en(q)
        flown_m += math.hypot(e - last[0], n - last[1])
        last = (e, n)
        out.append(at(e, n, climbed(flown_m)))
    # on along the line until the take-off altitude is reached, then level to the waypoint
    rest_m = max(run_m - flown_m, 0.0)
    if s_m + rest_m < length_m - 1.0 and out[-1].alt_amsl_m < top_m:
        out.append(at(ue * (s_m + rest_m), un * (s_m + rest_m), top_m))
    return [*out, wp]
