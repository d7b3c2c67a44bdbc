"""Point-mass kinematics for a multirotor and a fixed-wing aircraft (pure, no I/O, no clock).

Frame: local tangent plane at home, `north_m`/`east_m` metres, `alt_amsl_m` metres AMSL; ground
is flat at the home altitude. Velocities are ground-relative (`vn_mps`, `ve_mps`, `vup_mps`).
A `Goal` is what the flight mode asks for: a point to fly to (or through), a speed, and whether
to stop there (multirotor hovers; fixed wing loiters on a circle around it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl.spec import Limits

G_MPS2 = 9.80665
_WGS84_A_M = 6378137.0
_WGS84_E2 = 6.69437999014e-3


class LocalTangent:
    """Flat-earth conversion around an origin using the WGS84 radii of curvature there.

    Error grows as d²/R (about 1 m at 3.5 km): fine for a simulated vehicle whose reported
    lat/lon *is* the truth the ground side must reproduce.
    """

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0_deg = lat0_deg
        self.lon0_deg = lon0_deg
        s = math.sin(math.radians(lat0_deg))
        denom = math.sqrt(1.0 - _WGS84_E2 * s * s)
        r_meridian = _WGS84_A_M * (1.0 - _WGS84_E2) / denom**3
        r_normal = _WGS84_A_M / denom
        self._m_per_deg_lat = math.radians(1.0) * r_meridian
        self._m_per_deg_lon = math.radians(1.0) * r_normal * math.cos(math.radians(lat0_deg))

    def to_ne(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        return (
            (lat_deg - self.lat0_deg) * self._m_per_deg_lat,
            (lon_deg - self.lon0_deg) * self._m_per_deg_lon,
        )

    def to_latlon(self, north_m: float, east_m: float) -> tuple[float, float]:
        return (
            self.lat0_deg + north_m / self._m_per_deg_lat,
            self.lon0_deg + east_m / self._m_per_deg_lon,
        )


@dataclass(slots=True)
class KinState:
    north_m: float = 0.0
    east_m: float = 0.0
    alt_amsl_m: float = 0.0
    vn_mps: float = 0.0
    ve_mps: float = 0.0
    vup_mps: float = 0.0
    yaw_rad: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    airspeed_mps: float = 0.0


@dataclass(slots=True)
class Goal:
    north_m: float
    east_m: float
    alt_amsl_m: float
    speed_mps: float
    stop: bool  # hover (multirotor) / loiter (fixed wing) at the point
    descent_rate_mps: float | None = None  # override (forced descent)
    # Fixed wing in a mission: the start (north, east) of the leg that ends at the point. The
    # aircraft then tracks the line from there (L1 / NPFG path following), as PX4 and
    # ArduPlane do, instead of flying straight at the point from wherever it is; a point to
    # stop at is loitered around once reached (the goal then has no line).
    line_from_ne: tuple[float, float] | None = None


L1_PERIOD_S = 10.0
L1_DAMPING = 0.7
"""Path-following gains of a fixed wing (PX4 NPFG_PERIOD / NPFG_DAMPING defaults; ArduPlane's
NAVL1_PERIOD / NAVL1_DAMPING play the same role): the look-ahead distance is
``period * damping / pi * ground speed``."""


def l1_distance_m(ground_speed_mps: float) -> float:
    """Look-ahead distance of the fixed wing's path following at ``ground_speed_mps``."""
    return max(L1_PERIOD_S * L1_DAMPING / math.pi * ground_speed_mps, 10.0)


def turn_radius_m(speed_mps: float, lim: Limits) -> float:
    """Radius of a coordinated turn at the bank limit."""
    return speed_mps * speed_mps / (G_MPS2 * math.tan(math.radians(max(lim.max_bank_deg, 1.0))))


def _clamp(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _vertical(s: KinState, goal: Goal, lim: Limits, dt: float, want: float | None = None) -> None:
    """Vertical speed toward ``want`` (default: P gain 1/s on the altitude error, ~1 s to
    settle, within the climb/descent limits), rate-limited by the acceleration."""
    if want is None:
        want = _clamp(
            1.0 * (goal.alt_amsl_m - s.alt_amsl_m), -_descent(goal, lim), lim.climb_rate_mps
        )
    dv = _clamp(want - s.vup_mps, -lim.accel_mps2 * dt, lim.accel_mps2 * dt)
    s.vup_mps += dv
    s.alt_amsl_m += s.vup_mps * dt


def _descent(goal: Goal, lim: Limits) -> float:
    return goal.descent_rate_mps if goal.descent_rate_mps is not None else lim.descent_rate_mps


def step_multirotor(s: KinState, goal: Goal, lim: Limits, dt: float) -> None:
    """Position controller: accelerate toward the goal, brake to stop (or pass through)."""
    dn = goal.north_m - s.north_m
    de = goal.east_m - s.east_m
    dz = goal.alt_amsl_m - s.alt_amsl_m
    dist = math.hypot(dn, de)
    speed = min(goal.speed_mps, lim.max_speed_mps)
    if goal.stop:
        # v = sqrt(2 a d) brakes to a standstill at the point; 0.8 keeps a margin.
        speed = min(speed, math.sqrt(2.0 * lim.accel_mps2 * 0.8 * dist), 1.5 * dist)
    # PX4 (FlightTaskAuto): the velocity setpoint points at the target in 3D with magnitude
    # sqrt(xy^2 + z^2), then is scaled down as a whole until its horizontal norm is within the
    # horizontal speed and its vertical part within the climb/descent speed: the vehicle flies
    # the straight 3D line to the waypoint, slowing horizontally when the climb limits it.
    vz_max = min(lim.climb_rate_mps if dz >= 0.0 else _descent(goal, lim), 1.0 * abs(dz))
    dist3 = math.hypot(dist, dz)
    if dist3 > 1e-3:
        mag = math.hypot(speed, vz_max)
        wn, we, wz = dn / dist3 * mag, de / dist3 * mag, dz / dist3 * mag
        xy = math.hypot(wn, we)
        if xy > speed:
            f = speed / xy
            wn, we, wz = wn * f, we * f, wz * f
        if abs(wz) > vz_max:
            f = vz_max / abs(wz)
            wn, we, wz = wn * f, we * f, wz * f
    else:
        wn = we = wz = 0.0
    an = wn - s.vn_mps
    ae = we - s.ve_mps
    amag = math.hypot(an, ae)
    amax = lim.accel_mps2 * dt
    if amag > amax:
        an, ae = an / amag * amax, ae / amag * amax
    s.vn_mps += an
    s.ve_mps += ae
    s.north_m += s.vn_mps * dt
    s.east_m += s.ve_mps * dt
    _vertical(s, goal, lim, dt, wz)
    gs = math.hypot(s.vn_mps, s.ve_mps)
    if gs > 0.5:
        s.yaw_rad = math.atan2(s.ve_mps, s.vn_mps)
    # tilt from the horizontal acceleration (small-angle attitude for ATTITUDE telemetry)
    acc_n, acc_e = an / dt, ae / dt
    c, sn = math.cos(s.yaw_rad), math.sin(s.yaw_rad)
    s.pitch_rad = -math.atan2(acc_n * c + acc_e * sn, G_MPS2)
    s.roll_rad = math.atan2(-acc_n * sn + acc_e * c, G_MPS2)
    s.airspeed_mps = gs


def step_fixed_wing(
    s: KinState, goal: Goal, lim: Limits, dt: float, wind_ne_mps: tuple[float, float]
) -> None:
    """Coordinated-turn point mass: airspeed within limits, bank-limited turn rate, climb limits,
    and a circle of `loiter_radius_m` around the goal when it asks to stop."""
    v_cmd = _clamp(goal.speed_mps, lim.min_airspeed_mps, lim.max_speed_mps)
    dv = _clamp(v_cmd - s.airspeed_mps, -lim.accel_mps2 * dt, lim.accel_mps2 * dt)
    s.airspeed_mps = max(lim.min_airspeed_mps, s.airspeed_mps + dv)
    v = s.airspeed_mps
    dn = goal.north_m - s.north_m
    de = goal.east_m - s.east_m
    dist = math.hypot(dn, de)
    r = lim.loiter_radius_m
    max_rate = G_MPS2 * math.tan(math.radians(lim.max_bank_deg)) / max(v, 1.0)
    if goal.stop and goal.line_from_ne is None and dist < 3.0 * r:
        # Loiter clockwise: tangent course plus a radial correction proportional to the error.
        radial = math.atan2(-de, -dn)  # bearing from centre to aircraft
        tangent = radial + math.pi / 2.0
        err = _clamp((dist - r) / r, -1.0, 1.0)
        want = tangent + err * (math.pi / 3.0)
        rate = _clamp(2.0 * _wrap_pi(want - s.yaw_rad), -max_rate, max_rate)  # P gain 2/s
    elif goal.line_from_ne is not None:
        rate = _clamp(_l1_rate(s, goal, goal.line_from_ne, v), -max_rate, max_rate)
    else:
        rate = _clamp(2.0 * _wrap_pi(math.atan2(de, dn) - s.yaw_rad), -max_rate, max_rate)
    s.yaw_rad = _wrap_pi(s.yaw_rad + rate * dt)
    s.roll_rad = math.atan2(rate * v, G_MPS2)
    s.vn_mps = v * math.cos(s.yaw_rad) + wind_ne_mps[0]
    s.ve_mps = v * math.sin(s.yaw_rad) + wind_ne_mps[1]
    s.north_m += s.vn_mps * dt
    s.east_m += s.ve_mps * dt
    _vertical(s, goal, lim, dt)
    s.pitch_rad = math.atan2(s.vup_mps, max(v, 1.0))


def _l1_rate(s: KinState, goal: Goal, line_from_ne: tuple[float, float], v: float) -> float:
    """Turn rate of L1 path following on the line from ``line_from_ne`` through the goal
    point (extended beyond it): aim at the point of the line one look-ahead distance away,
    lateral acceleration ``2 v^2 sin(eta) / L1`` (Park, Deyst and How 2004; ArduPlane's
    AP_L1_Control, PX4's NPFG keep the same geometry)."""
    n0, e0 = line_from_ne
    ln, le = goal.north_m - n0, goal.east_m - e0
    length = math.hypot(ln, le)
    if length < 1e-6:
        bearing = math.atan2(goal.east_m - s.east_m, goal.north_m - s.north_m)
        return 2.0 * _wrap_pi(bearing - s.yaw_rad)
    un, ue = ln / length, le / length
    rn, re = s.north_m - n0, s.east_m - e0
    along = rn * un + re * ue
    cross = -rn * ue + re * un  # > 0: right of the line
    l1 = l1_distance_m(v)
    # the look-ahead point on the line (a track further than L1 away is joined at 45 deg)
    ahead = math.sqrt(max(l1 * l1 - cross * cross, 0.0)) if abs(cross) < l1 else abs(cross)
    tn = n0 + (along + ahead) * un
    te = e0 + (along + ahead) * ue
    eta = _wrap_pi(math.atan2(te - s.east_m, tn - s.north_m) - s.yaw_rad)
    eta = _clamp(eta, -math.pi / 2.0, math.pi / 2.0)
    return 2.0 * v * math.sin(eta) / l1
