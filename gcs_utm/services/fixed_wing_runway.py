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
from collections.abc import Iterator
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


NPFG_GAIN_PER_S = 4.0 * math.pi * NPFG_DAMPING / PX4_PERIOD_S
"""NPFG's gain ``4 pi damping / period`` (0.88/s): its lateral acceleration is this times the
airspeed and the sine of the error to its bearing (``NPFG::lateralAccel``)."""
ROLL_LAG_S = 0.3
"""The lag of the lateral acceleration behind NPFG's command (roll dynamics), fitted to the
recorded take-off (``tests/data/flown/px4_plane_second_takeoff_2.json``)."""
PX4_TAKEOFF_MPS = 13.5
"""PX4 v1.15.2 SIH's ground speed in its take-off climb (at its take-off airspeed,
FW_TKO_AIRSPD unset: the minimum airspeed as the setpoint), measured 12.6-14.7 m/s in the
turn; fitted to the recorded take-offs."""
PX4_FLOWN_MPS = 14.5
"""The ground speed PX4 v1.15.2 SIH flies at its 15 m/s trim airspeed (no wind), measured."""
CLIMB_MPS = 5.0
"""PX4's FW_T_CLMB_MAX (default): its climb towards the next waypoint's altitude."""
_STEP_S = 0.1  # integration step
_POINT_EVERY_DEG = 15.0  # a modelled point every 15 deg of heading
_DONE_DEG = 5.0  # heading for the take-off position: the rest is the straight line to it
SETTLE_S = 4.0
"""After its turn for the next waypoint PX4 v1.15.2 SIH's course converges on the bearing
to it slowly (its yaw 4-7 deg off its course, a small roll held for seconds): from 7 deg of
error 3 s after the take-off to 1 deg 6-10 s later. Modelled as a first-order lag of the
course with this time constant, fitted to two recorded re-take-offs (1.5-2 s and 5-7 s):
without it the plan, straight for the waypoint from the turn's end, was 9.1-12.1 m beside
the slower ones (UAS_IN_CV 10.2 m in the 30-minute soak)."""
_SETTLE_POINT_S = 2.0  # a modelled point every 2 s of the convergence
_SETTLED_DEG = 0.5


def px4_takeoff(start: P, heading_deg: float | None, climb: list[P], wp: P, nxt: P
                ) -> list[P]:  # fmt: skip
    """PX4's take-off to ``wp`` (the NAV_TAKEOFF item with its position) from ``start``, given
    the straight ``climb`` (ground-roll end, climb end, along the line to ``wp``), then on to
    ``nxt`` (the next item with a position): from the ground roll's end (along
    ``heading_deg``, where it stands parked, when that is off the line; else the line's) the
    points up to the take-off altitude (points of the take-off), then those until it heads
    for ``nxt`` (points of ``nxt``); ``nxt`` itself follows. The take-off's position is not
    flown over.

    PX4 v1.15 (``FixedwingPositionControl``): once off the ground the runway take-off follows
    the line from its start through the take-off position (NPFG ``navigateLine``); the
    NAV_TAKEOFF completes as soon as the plane is above the item's altitude
    (``MissionBlock::is_mission_item_reached``), wherever it is; the next waypoint is then
    pursued from there (``control_auto_position``: a previous setpoint of type TAKEOFF is
    not used, ``navigateWaypoint``). NPFG's bearing to a line: across it while the track
    error is beyond its bound (``V period damping``), along it on it, at the look-ahead angle
    ``pi/2 (1 - e/bound)^2`` from across between; its lateral acceleration ``gain V
    sin(error)`` (``gain V`` beyond 90 deg) is capped by the roll limit. Integrated here at
    the take-off's ground speed until the climb's run is flown, then at the cruise's, while
    it climbs to the next waypoint's altitude (``FW_T_CLMB_MAX``). Measured on PX4 v1.15.2 SIH
    (the soak's second and third take-offs, parked on 152-157 deg, take-off position 600 m
    north): it rolled south-east, turned left through north to -43 deg (converging on the
    line from the east), reached the take-off altitude about 90 m out, turned right and flew
    straight for the next waypoint, 2 m west of the line from there to it 325 m north of its
    start, where the line to the take-off position was 10 m further west. After that turn its
    course converges on the bearing slowly (:data:`SETTLE_S`). The model is within 3.4 m
    across and 5.5 m up of the recorded take-offs that converged quickly and 5.9 m of one that
    converged slowly, where the full-bank turn back onto the line and on to the take-off
    position was 10.7-14.1 m across."""
    k = math.cos(math.radians(start.lat_deg))

    def en(q: Point) -> tuple[float, float]:
        return ((q.lon_deg - start.lon_deg) * _M_PER_DEG_LON * k,
                (q.lat_deg - start.lat_deg) * _M_PER_DEG_LAT)  # fmt: skip

    we, wn = en(wp)
    length_m = max(math.hypot(we, wn), 1e-6)
    line = (we / length_m, wn / length_m)
    line_deg = math.degrees(math.atan2(*line))
    roll_m = math.hypot(*en(climb[0]))
    psi_deg = line_deg
    if heading_deg is not None and abs(_wrap_deg(heading_deg - line_deg)) >= ALIGNED_DEG:
        roll_m, psi_deg = min(LIFT_OFF_M, roll_m), heading_deg
    run_m = max(math.hypot(*en(climb[1])), roll_m + 1.0)
    base_m, top_m = climb[0].alt_amsl_m, climb[1].alt_amsl_m
    flight = _Npfg(psi_deg, roll_m, PX4_TAKEOFF_MPS)

    def at(q: P, alt: float) -> P:
        lat = start.lat_deg + flight.n / _M_PER_DEG_LAT
        lon = start.lon_deg + flight.e / (_M_PER_DEG_LON * k)
        return q.moved(lat, lon, alt).synthetic()

    out: list[P] = [at(wp, base_m)]
    for _ in flight.along(line, run_m - roll_m):
        climbed = (flight.flown_m - roll_m) / (run_m - roll_m)
        out.append(at(wp, base_m + (top_m - base_m) * min(climbed, 1.0)))
    out.append(at(wp, top_m))
    flight.fly_at(min(max(nxt.speed_mps, 1.0), PX4_FLOWN_MPS))
    top_at_m = flight.flown_m

    def towards_next(flown_m: float) -> float:
        """From the take-off's completion PX4 climbs (or descends) to ``nxt``'s altitude."""
        change_m = (flown_m - top_at_m) * CLIMB_MPS / flight.speed
        return top_m + max(min(nxt.alt_amsl_m - top_m, change_m), -change_m)

    for _ in flight.pursuit(en(nxt)):
        out.append(at(nxt, towards_next(flight.flown_m)))
    for _ in flight.settle(en(nxt), SETTLE_S):
        out.append(at(nxt, towards_next(flight.flown_m)))
    if flight.flown_m > top_at_m + 1.0:  # where it has converged: then straight for ``nxt``
        out.append(at(nxt, towards_next(flight.flown_m)))
    return out


class _Npfg:
    """A plane flown by NPFG (:func:`px4_takeoff`): position east/north of the start (m),
    course (rad, clockwise from north), distance flown and lateral acceleration."""

    def __init__(self, course_deg: float, roll_m: float, speed_mps: float) -> None:
        self.psi = math.radians(course_deg)
        self.e, self.n = math.sin(self.psi) * roll_m, math.cos(self.psi) * roll_m
        self.flown_m, self.accel = roll_m, 0.0
        self.limit = 9.81 * math.tan(math.radians(PX4_ROLL_LIMIT_DEG))
        self.speed = self.bound_m = 0.0
        self.fly_at(speed_mps)

    def fly_at(self, speed_mps: float) -> None:
        """Fly at ``speed_mps`` from now on (NPFG's track-error bound scales with it)."""
        self.speed, self.bound_m = speed_mps, speed_mps * PX4_PERIOD_S * NPFG_DAMPING

    def step(self, bearing: float) -> None:
        """One step of flight towards the course ``bearing``."""
        err = (bearing - self.psi + math.pi) % (2.0 * math.pi) - math.pi
        pull = math.copysign(1.0, err) if abs(err) > math.pi / 2.0 else math.sin(err)
        command = max(-self.limit, min(self.limit, NPFG_GAIN_PER_S * self.speed * pull))
        self.accel += (command - self.accel) * min(_STEP_S / ROLL_LAG_S, 1.0)
        self.psi += self.accel / self.speed * _STEP_S
        self.e += math.sin(self.psi) * self.speed * _STEP_S
        self.n += math.cos(self.psi) * self.speed * _STEP_S
        self.flown_m += self.speed * _STEP_S

    def along(self, line: tuple[float, float], distance_m: float) -> Iterator[None]:
        """Follow the line through the start along ``line`` (a unit vector) for
        ``distance_m``, yielding every :data:`_POINT_EVERY_DEG` of turn."""
        ue, un = line
        last, end_m = self.psi, self.flown_m + distance_m
        while self.flown_m < end_m:
            cross = self.e * un - self.n * ue  # to the line's right positive
            look = math.pi / 2.0 * (min(abs(cross) / self.bound_m, 1.0) - 1.0) ** 2
            side = -1.0 if cross > 0.0 else 1.0  # across towards the line
            be = math.cos(look) * side * un + math.sin(look) * ue
            bn = -math.cos(look) * side * ue + math.sin(look) * un
            self.step(math.atan2(be, bn))
            if abs(self.psi - last) >= math.radians(_POINT_EVERY_DEG):
                last = self.psi
                yield None

    def settle(self, goal: tuple[float, float], tau_s: float) -> Iterator[None]:
        """After the turn: the course converges on the bearing to ``goal`` with the time
        constant ``tau_s``, yielding every :data:`_SETTLE_POINT_S`, until within
        :data:`_SETTLED_DEG` of it."""
        if tau_s <= 0.0:
            return
        since_s = 0.0
        for _ in range(int(60.0 / _STEP_S)):
            be, bn = goal[0] - self.e, goal[1] - self.n
            err = (math.atan2(be, bn) - self.psi + math.pi) % (2.0 * math.pi) - math.pi
            if math.hypot(be, bn) < self.bound_m or abs(math.degrees(err)) < _SETTLED_DEG:
                return
            self.psi += err * min(_STEP_S / tau_s, 1.0)
            self.e += math.sin(self.psi) * self.speed * _STEP_S
            self.n += math.cos(self.psi) * self.speed * _STEP_S
            self.flown_m += self.speed * _STEP_S
            since_s += _STEP_S
            if since_s >= _SETTLE_POINT_S:
                since_s = 0.0
                yield None

    def pursuit(self, goal: tuple[float, float]) -> Iterator[None]:
        """Fly for ``goal`` until heading for it (or close), yielding every
        :data:`_POINT_EVERY_DEG` of turn."""
        last = self.psi
        for _ in range(int(40.0 * self.bound_m / (self.speed * _STEP_S))):
            be, bn = goal[0] - self.e, goal[1] - self.n
            bearing = math.atan2(be, bn)
            err = (bearing - self.psi + math.pi) % (2.0 * math.pi) - math.pi
            if math.hypot(be, bn) < self.bound_m or abs(math.degrees(err)) < _DONE_DEG:
                return
            self.step(bearing)
            if abs(self.psi - last) >= math.radians(_POINT_EVERY_DEG):
                last = self.psi
                yield None
