"""A fixed wing's loiter filed as ArduPlane flies it (issue 31): on WP_LOITER_RAD when the
item carries no radius (ArduPilot reads NAV_LOITER_TIME back with param3 = +1, the direction
only: the soak's ArduPlane was filed circling a 1 m circle), entered on its turn, left on
the tangent to the next waypoint, then back on the line from the centre."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import pytest

from gcs_utm.model import OperationId, Position
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.mission_points import NavPoint, mission_points, plan_from_points

HOME = Position(lat_deg=45.4671, lon_deg=-73.7963, alt_amsl_m=32.4)
M_LAT = 110_540.0
M_LON = 111_320.0 * math.cos(math.radians(HOME.lat_deg))
CENTRE = (-800.0, 1600.0)  # east, north of home: the soak's loiter


@dataclass
class _Item:
    command: int
    x: int = 0
    y: int = 0
    z: float = 0.0
    frame: int = 3
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    seq: int = 0


def _at(east: float, north: float) -> tuple[int, int]:
    return round((HOME.lat_deg + north / M_LAT) * 1e7), round((HOME.lon_deg + east / M_LON) * 1e7)


def _en(p: NavPoint) -> tuple[float, float]:
    return (p.lon_deg - HOME.lon_deg) * M_LON, (p.lat_deg - HOME.lat_deg) * M_LAT


def _soak_mission(
    param3: float = 1.0, param4: float = 0.0, loiter: tuple[int, float] = (19, 60.0)
) -> list[NavPoint]:
    """The nuisance soak's ArduPlane mission as read back (NAV_LOITER_TIME param3 = 1)."""
    rows = [
        (16, 0.0, 0.0, 0.0, 0.0),
        (22, 0.0, 0.0, 30.0, 15.0),
        (16, 0.0, 1600.0, 60.0, 0.0),
        (loiter[0], *CENTRE, loiter[1], 20.0 if loiter[0] == 19 else 0.0),
        (189, -800.0, 0.0, 0.0, 0.0),
        (16, -400.0, -400.0, 30.0, 0.0),
        (21, 0.0, 0.0, 0.0, 0.0),
    ]
    items = []
    for seq, (cmd, east, north, alt, p1) in enumerate(rows):
        lat, lon = _at(east, north)
        p3 = param3 if cmd == 19 else 0.0
        p4 = param4 if cmd in (19, 31) else 0.0
        items.append(_Item(cmd, lat, lon, alt, param1=p1, param3=p3, param4=p4, seq=seq))
    pts = mission_points(items, home=HOME, cruise_speed_mps=22.0, skip_first=True)
    assert pts is not None
    return fw.fixed_wing_points(
        pts, ground_alt_m=HOME.alt_amsl_m, climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, home_deg=(HOME.lat_deg, HOME.lon_deg),
    )  # fmt: skip


def _polar(p: NavPoint) -> tuple[float, float]:
    e, n = _en(p)
    return math.hypot(e - CENTRE[0], n - CENTRE[1]), math.atan2(n - CENTRE[1], e - CENTRE[0])


def test_a_loiter_without_a_radius_is_flown_on_the_default_radius() -> None:
    circle = [p for p in _soak_mission() if p.command == 19 and p.explicit]
    assert all(_polar(p)[0] == pytest.approx(80.0, abs=0.5) for p in circle)
    # a 20 s loiter at 22 m/s on 80 m (a turn takes 22.8 s): 0.87 turns, then round on to
    # the tangent towards the approach waypoint
    swept = sum(
        (_polar(a)[1] - _polar(b)[1]) % (2.0 * math.pi)  # clockwise: the angle decreases
        for a, b in itertools.pairwise(circle)
    )
    assert 0.87 * 2.0 * math.pi <= swept <= 1.87 * 2.0 * math.pi


def test_the_plane_joins_on_its_turn_and_leaves_on_the_tangent() -> None:
    plane = _soak_mission()
    circle = [p for p in plane if p.command == 19 and p.explicit]
    # arriving from the east on a clockwise circle: the southern side, heading west
    _, entry = _polar(circle[0])
    capture = next(p for p in plane if p.command == 19)
    assert not capture.explicit  # on the line to the centre, 1.4 radii from it
    assert _polar(capture)[0] == pytest.approx(112.0, abs=0.5)
    assert math.degrees(_polar(capture)[1]) == pytest.approx(0.0, abs=1.0)
    tangent_deg = math.degrees(math.acos(80.0 / 112.0))  # joined from there on its turn
    assert math.degrees(entry) == pytest.approx(-tangent_deg, abs=0.5)
    e0, n0 = _en(circle[0])
    e1, n1 = _en(circle[1])
    assert e1 < e0 and abs(n1 - n0) < abs(e1 - e0)
    # leaves heading for the approach waypoint (-400, -400): the tangent from it
    ex, nx = _en(circle[-1])
    heading = (-400.0 - ex, -400.0 - nx)
    radial = (ex - CENTRE[0], ny := nx - CENTRE[1])
    assert abs(heading[0] * radial[0] + heading[1] * ny) / math.hypot(*heading) < 2.0
    # on along the tangent for half a radius, then back on the line from the centre to it,
    # two radii further on: synthetic points of the approach's item
    run, join = plane[plane.index(circle[-1]) + 1 : plane.index(circle[-1]) + 3]
    assert run.seq == join.seq == 5 and not run.explicit and not join.explicit
    re_, rn = _en(run)
    assert math.hypot(re_ - ex, rn - nx) == pytest.approx(40.0, abs=0.5)
    assert abs((re_ - ex) * radial[0] + (rn - nx) * ny) < 1.0  # square to the radius
    je, jn = _en(join)
    u = (400.0 / math.hypot(400.0, 2000.0), -2000.0 / math.hypot(400.0, 2000.0))
    off_line = (je - CENTRE[0]) * u[1] - (jn - CENTRE[1]) * u[0]
    assert abs(off_line) < 0.5
    assert math.hypot(je - ex, jn - nx) == pytest.approx(160.0, abs=25.0)


def test_with_param4_1_it_flies_straight_from_where_it_left() -> None:
    plane = _soak_mission(param4=1.0)
    last = max(k for k, p in enumerate(plane) if p.command == 19)
    assert plane[last + 1].command == 16 and plane[last + 1].explicit


def test_a_counter_clockwise_loiter_and_an_item_radius() -> None:
    circle = [p for p in _soak_mission(param3=-1.0) if p.command == 19 and p.explicit]
    _, entry = _polar(circle[0])
    tangent_deg = math.degrees(math.acos(80.0 / 112.0))
    assert math.degrees(entry) == pytest.approx(tangent_deg, abs=0.5)  # the northern side
    assert all(_polar(p)[0] == pytest.approx(80.0, abs=0.5) for p in circle)
    circle = [p for p in _soak_mission(param3=150.0) if p.command == 19 and p.explicit]
    assert all(_polar(p)[0] == pytest.approx(150.0, abs=0.5) for p in circle)


def test_the_plan_re_timed_after_the_loiter_goes_through_the_join() -> None:
    """Re-timed when the approach becomes current (the plane 12 m past its exit, heading for
    the approach): from the plane to the join, not back to the modelled exit point (a
    waypoint reached early is turned round; a circle is left)."""
    plane = _soak_mission()
    exit_point = [p for p in plane if p.command == 19][-1]  # where the plane left
    ex, nx = _en(exit_point)
    k = 12.0 / math.hypot(-400.0 - ex, -400.0 - nx)
    lat = HOME.lat_deg + (nx + k * (-400.0 - nx)) / M_LAT
    lon = HOME.lon_deg + (ex + k * (-400.0 - ex)) / M_LON
    here = Position(lat_deg=lat, lon_deg=lon, alt_amsl_m=92.4)
    plan = plan_from_points(
        plane, OperationId("p"), t_s=0.0, current_seq=5, position=here, turn_from_m=50.0
    )
    assert plan is not None
    (_, here_n), run, join = [
        ((w.lon_deg - HOME.lon_deg) * M_LON, (w.lat_deg - HOME.lat_deg) * M_LAT)
        for w in plan.waypoints[:3]
    ]
    # on along the tangent (ahead of the plane, not back to the exit point), then the join
    # on the line from the centre, not (-400, -400)
    assert run[1] < here_n - 10.0
    assert join[1] < CENTRE[1] - 100.0 and abs(join[0] - CENTRE[0]) < 60.0


def test_a_loiter_to_alt_changes_altitude_on_the_way_as_far_as_it_can() -> None:
    """ArduPlane descends on its glide slope to the loiter point (climbs first with
    FLIGHT_OPTIONS bit 14): 20 m down over the 745 m to the circle (3 m/s at 22 m/s allows
    102 m), so the circle is flown at 40 m; 240 m up is more than the way allows."""
    down = [p for p in _soak_mission(loiter=(31, 40.0)) if p.command == 31 and p.explicit]
    assert all(p.alt_amsl_m == pytest.approx(HOME.alt_amsl_m + 40.0) for p in down)
    up = [p for p in _soak_mission(loiter=(31, 300.0)) if p.command == 31 and p.explicit]
    rise = up[0].alt_amsl_m - (HOME.alt_amsl_m + 60.0)  # 745 m at 5 m/s over 22 m/s: 169 m
    assert 165.0 < rise < 172.0
    assert up[-1].alt_amsl_m == pytest.approx(HOME.alt_amsl_m + 300.0)
