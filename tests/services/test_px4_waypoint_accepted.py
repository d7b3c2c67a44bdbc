"""A PX4 plane accepts a waypoint up to its NPFG switch distance before it and turns for the
next item from where it is (issue 31). The nuisance soak's PX4 SIH plane accepted the
waypoint after its take-off 34 m before it and turned left at its roll limit for its loiter
300 m west; its plan, re-timed at the new current item, went on through the waypoint as
ArduPlane flies round one (WP_RADIUS): 10 m off the plane in the turn at low load, UAS_IN_CV
(17.1 m) in the 30-minute soak. ``tests/data/flown`` holds its positions from its ULog."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

from gcs_utm.model import OperationId, Position
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.mission_points import NavPoint, plan_from_points

DATA = Path(__file__).resolve().parents[1] / "data" / "flown" / "px4_plane_waypoint_accepted.json"
FLOWN = json.loads(DATA.read_text())
K = math.cos(math.radians(FLOWN["reached"]["lat_deg"]))


def _en(q: object) -> tuple[float, float]:
    lat, lon = (q["lat_deg"], q["lon_deg"]) if isinstance(q, dict) else (q.lat_deg, q.lon_deg)  # type: ignore[attr-defined]
    r = FLOWN["reached"]
    return (lon - r["lon_deg"]) * 111_320.0 * K, (lat - r["lat_deg"]) * 110_540.0


def _off_m(poly: list[tuple[float, float]], e: float, n: float) -> float:
    best = math.inf
    for (ax, ay), (bx, by) in itertools.pairwise(poly):
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        u = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((e - ax) * dx + (n - ay) * dy) / length2))
        best = min(best, math.hypot(e - ax - u * dx, n - ay - u * dy))
    return best


def _plan(course_deg: float | None) -> list[tuple[float, float]]:
    """The soak's mission from the waypoint on (take-off, this waypoint, the 20 s loiter, the
    waypoint after it), re-timed at the loiter (seq 2) from where the plane was."""
    r, lo, th = FLOWN["reached"], FLOWN["loiter"], FLOWN["then"]
    mission = [
        NavPoint(1, r["lat_deg"], r["lon_deg"], r["alt_amsl_m"], 22.0, True, 16),
        NavPoint(2, lo["lat_deg"], lo["lon_deg"], lo["alt_amsl_m"], 22.0, True, 19, amount=20.0),
        NavPoint(3, th["lat_deg"], th["lon_deg"], th["alt_amsl_m"], 22.0, True, 16),
    ]
    points = fw.fixed_wing_points(
        mission, ground_alt_m=None, climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=80.0, loiter_landing=True, loiter_exit_on_goal=True,
    )  # fmt: skip
    here = Position(**FLOWN["here"])
    plan = plan_from_points(
        points, OperationId("sys2"), t_s=0.0, current_seq=2, position=here, turn_from_m=80.0,
        course_deg=course_deg,
    )  # fmt: skip
    assert plan is not None
    return [_en({"lat_deg": w.lat_deg, "lon_deg": w.lon_deg}) for w in plan.waypoints]


def test_px4_turns_for_the_next_item_from_where_it_accepted_its_waypoint() -> None:
    """From its heading at the re-timing (PX4's course known): within 5 m of the plane
    through the turn and on to the loiter, where the plan on through the waypoint (ArduPlane's,
    no course) was 10 m off."""
    track = [_en(q) for q in FLOWN["track"]]
    assert max(_off_m(_plan(FLOWN["course_deg"]), *q) for q in track) < 5.0
    assert max(_off_m(_plan(None), *q) for q in track) > 9.0
    # the waypoint itself is not in the plan (it never flies over it: 18 m inside at most)
    assert min(math.hypot(*p) for p in _plan(FLOWN["course_deg"])) > 15.0
