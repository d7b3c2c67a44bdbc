"""PX4's fixed-wing landing pattern filed as PX4 flies it (issue 31.4): from a
NAV_LOITER_TO_ALT it goes on round the circle to its point towards the landing point, then
glides along the line from the loiter's centre to it; a straight line from the circle's last
modelled point to the landing point lay up to 50 m off that path (UAS_OUT_OV on real PX4)."""

from __future__ import annotations

import math

import pytest

from gcs_utm.model import OperationId, Position
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services import fixed_wing_point as fwp
from gcs_utm.services.fixed_wing_landing import landing_exit
from gcs_utm.services.mission_points import NavPoint, plan_from_points

LAT0, LON0 = 45.4671160, -73.7578370
K = math.cos(math.radians(LAT0))
M_LAT, M_LON = 110_540.0, 111_320.0 * K


def _deg(east_m: float, north_m: float) -> tuple[float, float]:
    return LAT0 + north_m / M_LAT, LON0 + east_m / M_LON


def _en(p: tuple[float, float]) -> tuple[float, float]:
    return (p[1] - LON0) * M_LON, (p[0] - LAT0) * M_LAT


def _distance_to_line_m(
    c: tuple[float, float], a: tuple[float, float], b: tuple[float, float]
) -> float:
    (ce, cn), (ae, an), (be, bn) = _en(c), _en(a), _en(b)
    de, dn = be - ae, bn - an
    return abs((ce - ae) * dn - (cn - an) * de) / math.hypot(de, dn)


@pytest.mark.parametrize("radius_m", [80.0, -80.0])
def test_the_exit_is_the_circles_point_towards_the_landing_point(radius_m: float) -> None:
    """From the circle's north point, clockwise (positive radius) round the east side,
    anticlockwise round the west side, to its south point: the landing point is 600 m south;
    every point on the circle, 15 degrees apart."""
    centre, land = (LAT0, LON0), _deg(0.0, -600.0)
    pts = landing_exit(centre, radius_m, _deg(0.0, 80.0), land)
    assert all(math.hypot(*_en(p)) == pytest.approx(80.0, abs=0.01) for p in pts)
    assert _en(pts[-1]) == pytest.approx((0.0, -80.0), abs=0.01)
    assert len(pts) == 12  # every 15 degrees round, the exit at 180 last
    assert math.copysign(1.0, _en(pts[0])[0]) == math.copysign(1.0, radius_m)  # east: clockwise
    assert landing_exit(centre, radius_m, _deg(0.0, 80.0), _deg(0.0, -50.0)) == []
    assert landing_exit(centre, radius_m, _deg(0.0, -80.0), land) == [pts[-1]]  # already there


def test_a_px4_landing_pattern_is_filed_along_its_landing_line() -> None:
    """NAV_LOITER_TO_ALT 600 m north of NAV_LAND, descending from 40 to 30 m (less than a
    turn): reached at 30 m (PX4 descends on the way and makes NAV_LAND current where it meets
    the circle), then round it to its south point as part of NAV_LAND, then the landing point:
    the last leg on the line from the loiter's centre to it. A plan from NAV_LAND on starts
    at the modelled point nearest the plane, wherever NAV_LAND became current. Without
    ``loiter_landing`` (ArduPlane leaves its loiter on the tangent towards the next
    waypoint) there is no way round to the landing line; a descent of more than a turn
    keeps its circle."""
    wp = NavPoint(1, *_deg(0.0, 1200.0), 40.0, 15.0, True)
    loiter = NavPoint(2, *_deg(0.0, 600.0), 30.0, 15.0, True, fwp.NAV_LOITER_TO_ALT, 80.0)
    land = NavPoint(3, *_deg(0.0, 0.0), 0.0, 15.0, True, fwp.NAV_LAND)
    args = {"ground_alt_m": 0.0, "climb_rate_mps": 3.0, "descent_rate_mps": 3.0,
            "loiter_radius_m": 80.0}  # fmt: skip
    px4 = fw.fixed_wing_points([wp, loiter, land], loiter_landing=True, **args)  # type: ignore[arg-type]
    plain = fw.fixed_wing_points([wp, loiter, land], **args)  # type: ignore[arg-type]
    assert px4[-1] == land and plain[-1] == land
    entry, exits = px4[1], px4[2:-1]
    assert (entry.seq, entry.alt_amsl_m) == (2, pytest.approx(30.0))
    assert _en((entry.lat_deg, entry.lon_deg)) == pytest.approx(
        _en((plain[1].lat_deg, plain[1].lon_deg))
    )
    assert exits and all(p.seq == 3 and not p.explicit for p in exits)
    assert all(p.alt_amsl_m == pytest.approx(30.0) for p in exits)
    assert _en((exits[-1].lat_deg, exits[-1].lon_deg)) == pytest.approx((0.0, 520.0), abs=0.05)
    # ArduPlane leaves on the tangent towards NAV_LAND: not round to the landing line
    assert all(math.dist(_en((p.lat_deg, p.lon_deg)), (0.0, 520.0)) > 1.0 for p in plain)
    half = exits[len(exits) // 2]
    at = Position(lat_deg=half.lat_deg, lon_deg=half.lon_deg, alt_amsl_m=30.0)
    plan = plan_from_points(px4, OperationId("p"), t_s=0.0, current_seq=3, position=at)
    assert plan is not None  # here (the nearest point), the rest of the circle, landing
    assert len(plan.waypoints) == len(exits) - len(exits) // 2 + 1
    deep = NavPoint(2, *_deg(0.0, 600.0), -300.0, 15.0, True, fwp.NAV_LOITER_TO_ALT, 80.0)
    orbits = fw.fixed_wing_points([wp, deep, land], loiter_landing=True, **args)  # type: ignore[arg-type]
    assert len([p for p in orbits if p.seq == 2]) > 9  # more than a turn, orbited down
