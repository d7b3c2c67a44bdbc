"""Fixed-wing mission guidance flies like PX4 / ArduPlane path following: it tracks the line
between waypoints, starts each turn early enough to roll out on the next line, and never
circles back to a waypoint it overshot. Stepping a Vehicle directly, no sockets."""

from __future__ import annotations

import itertools
import math

import sitl
from sitl.physics import LocalTangent
from sitl.vehicle import Vehicle

HOME = (40.4, -3.7, 600.0)
TAN = LocalTangent(HOME[0], HOME[1])
ALT = 700.0
SPEED = 20.0


def _fly(points_ne: list[tuple[float, float]], t_end_s: float) -> list[tuple[float, float, float]]:
    """A fixed wing placed in flight at the first point flies the rest; (t, north, east)."""
    mission = []
    for n, e in points_ne:
        lat, lon = TAN.to_latlon(n, e)
        mission.append(
            sitl.MissionItemSpec(lat_deg=lat, lon_deg=lon, alt_amsl_m=ALT, speed_mps=SPEED)
        )
    spec = sitl.VehicleSpec(
        instance=0,
        kind="fixed_wing",
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_amsl_m=HOME[2],
        cruise_speed_mps=SPEED,
        mission=tuple(mission),
        auto_start_at_s=0.0,
        start_airborne=True,
    )
    v = Vehicle(spec, sitl.SimTime(start_utc_s=1_700_000_000.0))
    out = []
    t = 0.0
    while t < t_end_s:
        t += 0.1
        v.advance(t)
        n, e = TAN.to_ne(v.lat_deg, v.lon_deg)
        out.append((t, n, e))
    return out


def _dist_to_path(p: tuple[float, float], pts: list[tuple[float, float]]) -> float:
    best = math.inf
    for a, b in itertools.pairwise(pts):
        dn, de = b[0] - a[0], b[1] - a[1]
        u = max(0.0, min(1.0, ((p[0] - a[0]) * dn + (p[1] - a[1]) * de) / (dn * dn + de * de)))
        best = min(best, math.hypot(p[0] - a[0] - u * dn, p[1] - a[1] - u * de))
    return best


# a lateral deformation as TD makes them: out at 45 deg, along, back, with short legs
ZIGZAG = [(0.0, 0.0), (300.0, 0.0), (360.0, 60.0), (420.0, 60.0), (480.0, 0.0), (1100.0, 0.0)]


def test_a_fixed_wing_follows_the_legs_and_rolls_out_on_the_next_line() -> None:
    track = _fly(ZIGZAG, 70.0)
    # on time: 910 m of path to n = 860 m at 20 m/s; circling back to a missed point costs
    # ~20 s
    t_end = next(t for t, n, _ in track if n >= 860.0)
    assert t_end < 910.0 / SPEED + 3.0, t_end
    # until the loiter around the last point begins (3 loiter radii from it)
    worst = max(_dist_to_path((n, e), ZIGZAG) for t, n, e in track if t < t_end)
    # a turn at 35 deg bank cuts inside the corner by R (1/cos(a/2) - 1), ~5 m at 45 deg;
    # flying at each point instead overshoots every corner (15 m) and then flies point to
    # point
    assert worst < 10.0, worst


def test_a_waypoint_too_close_to_turn_onto_is_passed_not_circled() -> None:
    # a 90 deg turn 40 m after the previous point: the aircraft cannot turn inside it (R ~ 58 m)
    pts = [(0.0, 0.0), (400.0, 0.0), (400.0, 40.0), (400.0, 800.0)]
    track = _fly(pts, 60.0)
    n_end, e_end = track[-1][1], track[-1][2]
    assert e_end > 500.0, (n_end, e_end)  # well along the last leg, not circling the corner
    # back on the line after the corner it could not make (before the final loiter)
    assert max(_dist_to_path((n, e), pts) for _, n, e in track if 300.0 < e < 540.0) < 3.0


def test_the_last_waypoint_is_flown_to_on_the_line_then_loitered_around() -> None:
    # PX4 and ArduPlane fly to the mission's last waypoint and loiter around it once there;
    # leaving the line three loiter radii (12 s) early put two fixed wings whose plans end
    # near each other on overlapping circles before their plans ended.
    pts = [(0.0, 0.0), (800.0, 0.0)]
    track = _fly(pts, 60.0)
    before = [(n, e) for t, n, e in track if n < 800.0 - 20.0 and t < 38.0]
    assert max(abs(e) for _, e in before) < 1.0
    # then it circles the point at its loiter radius (80 m by default)
    late = [math.hypot(n - 800.0, e) for t, n, e in track if t > 55.0]
    assert all(60.0 < r < 100.0 for r in late), late
