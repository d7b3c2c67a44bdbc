"""PX4's runway take-off from a parked heading (issue 31): it rolls along the heading it
stands on (RWTO_HDG 0), then turns at its roll limit for the take-off waypoint. The nuisance
soak's PX4 SIH plane, parked on its landing's heading (154 deg) for a take-off waypoint 600 m
north, was planned on the straight climb-out from its start towards that waypoint: 33 m off
its plan (UAS_OUT_OV, an auto-accepted hold). ``tests/data/flown`` holds its positions."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any
from unittest import mock

from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services import fixed_wing_runway as fwr
from gcs_utm.services.mission_points import NavPoint

DATA = Path(__file__).resolve().parents[1] / "data" / "flown"
FLIGHTS = [
    json.loads((DATA / name).read_text())
    for name in (
        "px4_plane_second_takeoff.json",
        "px4_plane_second_takeoff_2.json",
        "px4_plane_takeoff_third.json",
    )
]
FLOWN = FLIGHTS[0]


def _en(lat: float, lon: float, home: dict[str, float] | None = None) -> tuple[float, float]:
    home = home or FLOWN["home"]
    k = math.cos(math.radians(home["lat_deg"]))
    return (lon - home["lon_deg"]) * 111_320.0 * k, (lat - home["lat_deg"]) * 110_540.0


def _plan(
    heading_deg: float | None, flown: dict[str, Any] = FLOWN
) -> list[tuple[float, float, float]]:
    tk, nxt, home = flown["takeoff"], flown["next"], flown["home"]
    points = [
        NavPoint(1, tk["lat_deg"], tk["lon_deg"], tk["alt_amsl_m"], 22.0, True, 22),
        NavPoint(2, nxt["lat_deg"], nxt["lon_deg"], nxt["alt_amsl_m"], 22.0, True, 16),
    ]
    pts = fw.fixed_wing_points(
        points, ground_alt_m=home["alt_amsl_m"], climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, home_deg=(home["lat_deg"], home["lon_deg"]), loiter_landing=True,
        takeoff_heading_deg=heading_deg, loiter_exit_on_goal=True,
    )  # fmt: skip
    return [(0.0, 0.0, home["alt_amsl_m"])] + [
        (*_en(p.lat_deg, p.lon_deg, home), p.alt_amsl_m) for p in pts
    ]


def _off_m(
    plan: list[tuple[float, float, float]],
    q: dict[str, float],
    home: dict[str, float] | None = None,
) -> tuple[float, float]:
    """Horizontal distance to the plan's path and height above it there."""
    e, n = _en(q["lat_deg"], q["lon_deg"], home)
    best = (math.inf, 0.0)
    for (ax, ay, az), (bx, by, bz) in itertools.pairwise(plan):
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        u = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((e - ax) * dx + (n - ay) * dy) / length2))
        d = math.hypot(e - ax - u * dx, n - ay - u * dy)
        if d < best[0]:
            best = (d, q["alt_amsl_m"] - (az + u * (bz - az)))
    return best


def test_px4_rolls_on_its_parked_heading_then_turns_back_for_its_takeoff_line() -> None:
    """NPFG's convergence on the take-off line, then (at the take-off altitude) its pursuit of
    the next waypoint while it climbs to that waypoint's altitude: within 4 m across and 6 m
    up (the full-bank turn straight onto the line, then along it to the take-off position and
    level to it, was 10.7-14.1 m across)."""
    for flown in FLIGHTS:
        home = flown["home"]
        turned = [_off_m(_plan(flown["heading_deg"], flown), q, home) for q in flown["track"]]
        assert max(h for h, _ in turned) < 4.0
        assert max(abs(v) for _, v in turned) < 6.0
        straight = [_off_m(_plan(None, flown), q, home) for q in flown["track"]]
        assert max(h for h, _ in straight) > 25.0


def test_after_the_takeoff_px4_flies_for_the_next_waypoint_not_the_takeoff_position() -> None:
    """The third take-off's last 10 s: 2 m from the line from its completion to the next
    waypoint (within 3.5 m of the model, whose course converges on it more slowly), 9-10 m
    east of the line from there to the take-off position."""
    flown = FLIGHTS[2]
    plan = _plan(flown["heading_deg"], flown)
    tk = _en(flown["takeoff"]["lat_deg"], flown["takeoff"]["lon_deg"], flown["home"])
    assert all(math.hypot(e - tk[0], n - tk[1]) > 20.0 for e, n, _ in plan)  # never over it
    assert max(_off_m(plan, q, flown["home"])[0] for q in flown["track"][-10:]) < 4.0


def test_a_parked_heading_towards_the_takeoff_waypoint_is_the_straight_climb_out() -> None:
    tk = FLOWN["takeoff"]
    bearing = math.degrees(math.atan2(*_en(tk["lat_deg"], tk["lon_deg"])))
    assert _plan(bearing + 5.0) == _plan(None)
    assert _plan(bearing + 30.0) != _plan(None)


SLOW = json.loads((DATA / "px4_plane_takeoff_slow_settle.json").read_text())


def test_after_its_turn_px4s_course_converges_slowly_on_the_next_waypoint() -> None:
    """A re-take-off whose course stayed 2-4 deg left of the bearing to the next waypoint for
    10 s after its turn: within 6.5 m of the model with that convergence (a lag of the course,
    4 s), 9 m off the straight line to the waypoint from the turn's end (UAS_IN_CV 10.2 m in
    the 30-minute soak); the recorded take-offs that converged quickly stay within 4 m (above)."""
    home = SLOW["home"]

    def worst_m() -> float:
        return max(_off_m(_plan(SLOW["heading_deg"], SLOW), q, home)[0] for q in SLOW["track"])

    assert worst_m() < 6.5
    with mock.patch.object(fwr, "SETTLE_S", 0.0):
        assert worst_m() > 8.5
