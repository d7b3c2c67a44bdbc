"""ArduPlane's turn from its take-off course to the next waypoint (issue 31; the model in
gcs_utm/services/fixed_wing_turn.py). In the nuisance soak the ArduPlane's second take-off
rolled north-east (the course its landing left it on) and its next waypoint was 1600 m north:
it climbed out north-east, then turned north on its L1 pursuit from where the take-off ended;
filed as a straight line from the climb's end to the waypoint it was 45-50 m outside its plan
(UAS_IN_CV, UAS_OUT_OV and an auto-accepted back_to_plan). ``tests/data/flown`` holds its
positions as serve stored them."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import pytest

from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services import fixed_wing_turn as turn
from gcs_utm.services.mission_points import NavPoint

DATA = Path(__file__).resolve().parents[1] / "data" / "flown" / "arduplane_takeoff_turn.json"
FLOWN = json.loads(DATA.read_text())
START = FLOWN["start"]
K = math.cos(math.radians(START["lat_deg"]))


def _en(lat: float, lon: float) -> tuple[float, float]:
    return (lon - START["lon_deg"]) * 111_320.0 * K, (lat - START["lat_deg"]) * 110_540.0


def _plan(turn_after_takeoff: bool) -> list[tuple[float, float, float]]:
    """The mission as filed for the recorded take-off (east, north, AMSL)."""
    s, w = START, FLOWN["waypoint"]
    pts = [
        NavPoint(0, s["lat_deg"], s["lon_deg"], s["alt_amsl_m"], 22.0, True, 16),
        NavPoint(1, s["lat_deg"], s["lon_deg"], FLOWN["takeoff"]["alt_amsl_m"], 22.0, False, 22,
                 amount=FLOWN["takeoff"]["pitch_deg"]),
        NavPoint(2, w["lat_deg"], w["lon_deg"], w["alt_amsl_m"], 22.0, True, 16),
    ]  # fmt: skip
    flown = fw.fixed_wing_points(
        pts, ground_alt_m=s["alt_amsl_m"], climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, home_deg=(s["lat_deg"], s["lon_deg"]),
        takeoff_heading_deg=FLOWN["armed_heading_deg"], heads_for_takeoff_position=False,
        turn_after_takeoff=turn_after_takeoff,
    )  # fmt: skip
    return [(*_en(p.lat_deg, p.lon_deg), p.alt_amsl_m) for p in flown]


def _off_m(plan: list[tuple[float, float, float]], e: float, n: float) -> float:
    """Horizontal distance from (e, n) to the plan's polyline."""
    best = math.inf
    for (ax, ay, _), (bx, by, _) in itertools.pairwise(plan):
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        u = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((e - ax) * dx + (n - ay) * dy) / length2))
        best = min(best, math.hypot(e - ax - u * dx, n - ay - u * dy))
    return best


def test_the_plane_turning_after_its_take_off_is_on_its_plan() -> None:
    plan = _plan(turn_after_takeoff=True)
    offs = [_off_m(plan, *_en(q["lat_deg"], q["lon_deg"])) for q in FLOWN["track"]]
    # the straight line from the climb's end was 49 m off at the end of the turn
    assert max(offs) < 5.0, offs
    assert (
        max(_off_m(_plan(False), *_en(q["lat_deg"], q["lon_deg"])) for q in FLOWN["track"]) > 40.0
    )


def test_a_right_angle_turn_runs_on_then_widens_to_the_outside() -> None:
    """Rolling east, the next waypoint 2 km north: the roll-in runs on 1.4 s (31 m) east, the
    turn (capped at 45 deg of bank, then L1 = 0.75 * 15 * 22 / pi = 79 m) ends 80-100 m
    east of the line, heading for the waypoint; its points are the waypoint's, modelled, and
    climb along the straight line towards it."""
    s = START
    end = NavPoint(1, s["lat_deg"], s["lon_deg"], 60.0, 22.0, True, 22)
    wp = NavPoint(2, s["lat_deg"] + 2000.0 / 110_540.0, s["lon_deg"], 90.0, 22.0, True, 16)
    pts = turn.takeoff_turn(end, 90.0, wp, 22.0)
    en = [_en(p.lat_deg, p.lon_deg) for p in pts]
    assert en[0] == (pytest.approx(30.8, abs=1.5), pytest.approx(0.0, abs=0.5))
    assert 80.0 < en[-1][0] < 100.0
    assert all(e > 0.0 for e, _ in en) and [e for e, _ in en] == sorted(e for e, _ in en)
    last_course = math.degrees(math.atan2(en[-1][0] - en[-2][0], en[-1][1] - en[-2][1]))
    to_wp = math.degrees(math.atan2(-en[-1][0], 2000.0 - en[-1][1]))
    assert abs(last_course - to_wp) < 12.0  # the last chord of a turn ending 8 deg off
    assert all(p.seq == 2 and not p.explicit for p in pts)
    alts = [p.alt_amsl_m for p in pts]
    assert alts == sorted(alts) and alts[0] >= 60.0 and alts[-1] < 63.0


def test_no_turn_when_the_take_off_course_heads_for_the_waypoint() -> None:
    s = START
    end = NavPoint(1, s["lat_deg"], s["lon_deg"], 60.0, 22.0, True, 22)
    wp = NavPoint(2, s["lat_deg"] + 1000.0 / 110_540.0, s["lon_deg"], 90.0, 22.0, True, 16)
    assert turn.takeoff_turn(end, 0.5, wp, 22.0) == []
    assert turn.takeoff_turn(end, 90.0, wp, 22.0) != []
