"""PX4's fixed-wing landing pattern filed as PX4 flies it (issue 31.4): from a
NAV_LOITER_TO_ALT it leaves the circle on the tangent through the landing point, then glides
straight to it; a straight line from the circle's last modelled point to the landing point
lay up to a diameter off that path."""

from __future__ import annotations

import math

import pytest

from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.fixed_wing_landing import tangent_exit
from gcs_utm.services.vehicle_ops import NavPoint

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
def test_the_exit_is_the_tangent_through_the_landing_point(radius_m: float) -> None:
    """From the circle's north point, clockwise (positive radius) round the east side,
    anticlockwise round the west side, to the point whose tangent passes through the landing
    point 600 m south: the line from there to it touches the circle (its distance from the
    centre is the radius) and the points stay on the circle."""
    centre, land = (LAT0, LON0), _deg(0.0, -600.0)
    pts = tangent_exit(centre, radius_m, _deg(0.0, 80.0), land)
    assert all(math.hypot(*_en(p)) == pytest.approx(80.0, abs=0.01) for p in pts)
    exit_e, exit_n = _en(pts[-1])
    assert exit_n == pytest.approx(-80.0 * 80.0 / 600.0, abs=0.01)  # r^2/d towards the land
    assert math.copysign(1.0, exit_e) == math.copysign(1.0, radius_m)  # east when clockwise
    assert _distance_to_line_m(centre, pts[-1], land) == pytest.approx(80.0, abs=0.01)
    assert len(pts) == 3  # 45 and 90 degrees round, then the tangent point at 97.7
    assert tangent_exit(centre, radius_m, _deg(0.0, 80.0), _deg(0.0, -50.0)) == []


def test_a_px4_landing_pattern_is_filed_on_its_tangent() -> None:
    """NAV_LOITER_TO_ALT 600 m north of NAV_LAND, descending from 60 to 30 m: the circle,
    then round it to the tangent exit, then NAV_LAND; without ``tangent_landing`` (ArduPlane
    leaves its loiter towards the next waypoint) the circle goes straight to NAV_LAND."""
    wp = NavPoint(1, *_deg(0.0, 1200.0), 60.0, 15.0, True)
    loiter = NavPoint(2, *_deg(0.0, 600.0), 30.0, 15.0, True, fw.NAV_LOITER_TO_ALT, 80.0)
    land = NavPoint(3, *_deg(0.0, 0.0), 0.0, 15.0, True, fw.NAV_LAND)
    args = {"ground_alt_m": 0.0, "climb_rate_mps": 3.0, "descent_rate_mps": 3.0,
            "loiter_radius_m": 80.0}  # fmt: skip
    px4 = fw.fixed_wing_points([wp, loiter, land], tangent_landing=True, **args)  # type: ignore[arg-type]
    plain = fw.fixed_wing_points([wp, loiter, land], **args)  # type: ignore[arg-type]
    assert px4[-1] == land and plain[-1] == land
    exits = px4[len(plain) - 1 : -1]
    assert exits and all(p.seq == 2 for p in exits)  # points of the loiter, at its altitude
    assert all(p.alt_amsl_m == pytest.approx(30.0) for p in exits)
    centre = (loiter.lat_deg, loiter.lon_deg)
    tangent = (exits[-1].lat_deg, exits[-1].lon_deg)
    assert _distance_to_line_m(centre, tangent, (land.lat_deg, land.lon_deg)) == pytest.approx(
        80.0, abs=0.05
    )
    last_circle = (plain[-2].lat_deg, plain[-2].lon_deg)
    assert _distance_to_line_m(centre, last_circle, (land.lat_deg, land.lon_deg)) < 79.0
