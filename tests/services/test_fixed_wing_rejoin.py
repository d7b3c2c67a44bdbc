"""A fixed wing re-timed part-way along a leg goes back onto it (issue 31; the model in
gcs_utm/services/fixed_wing_rejoin.py). In the nuisance soak serve was killed and restarted
while the ArduPlane flew its NAV_LAND: it filed the mission again from the plane's position,
10 m off its landing line, straight to the landing point, while the plane converged on the
line from its approach waypoint: 12-14 m beside that plan (UAS_IN_CV). ``tests/data/flown``
holds its positions as serve stored them."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

from gcs_utm.model import OperationId, Position
from gcs_utm.services.fixed_wing_rejoin import rejoin
from gcs_utm.services.mission_points import NavPoint, plan_from_points

DATA = Path(__file__).resolve().parents[1] / "data" / "flown" / "arduplane_landing_rejoin.json"
FLOWN = json.loads(DATA.read_text())
APPROACH, LAND, FROM = FLOWN["approach"], FLOWN["land"], FLOWN["filed_from"]
K = math.cos(math.radians(LAND["lat_deg"]))


def _en(lat: float, lon: float) -> tuple[float, float]:
    return (lon - LAND["lon_deg"]) * 111_320.0 * K, (lat - LAND["lat_deg"]) * 110_540.0


def _points() -> list[NavPoint]:
    a, land = APPROACH, LAND
    return [
        NavPoint(5, a["lat_deg"], a["lon_deg"], a["alt_amsl_m"], 22.0, True, 16, landing=True),
        NavPoint(6, land["lat_deg"], land["lon_deg"], land["alt_amsl_m"], 22.0, True, 21,
                 landing=True),
    ]  # fmt: skip


def _plan(turn_from_m: float) -> list[tuple[float, float]]:
    position = Position(**FROM)
    plan = plan_from_points(
        _points(), OperationId("sys4"), t_s=0.0, current_seq=6, position=position,
        turn_from_m=turn_from_m,
    )  # fmt: skip
    assert plan is not None
    return [_en(w.lat_deg, w.lon_deg) for w in plan.waypoints]


def _off_m(plan: list[tuple[float, float]], e: float, n: float) -> float:
    best = math.inf
    for (ax, ay), (bx, by) in itertools.pairwise(plan):
        dx, dy = bx - ax, by - ay
        u = max(0.0, min(1.0, ((e - ax) * dx + (n - ay) * dy) / (dx * dx + dy * dy)))
        best = min(best, math.hypot(e - ax - u * dx, n - ay - u * dy))
    return best


def test_a_plane_filed_off_its_landing_line_is_planned_back_onto_it() -> None:
    fixed_wing = _plan(turn_from_m=80.0)
    multirotor = _plan(turn_from_m=0.0)  # straight from where it is
    track = [_en(q["lat_deg"], q["lon_deg"]) for q in FLOWN["track"]]
    assert len(fixed_wing) == 3 and len(multirotor) == 2
    assert max(_off_m(fixed_wing, *q) for q in track) < 5.0
    assert max(_off_m(multirotor, *q) for q in track) > 12.0


def test_no_rejoin_on_the_leg_after_a_take_off_or_a_loiter_or_on_the_line() -> None:
    a, land = _points()
    assert rejoin(FROM["lat_deg"], FROM["lon_deg"], a, land) != []
    for cmd in (22, 19, 31):  # take-off (a pursuit), loiters (their exits are modelled)
        prev = NavPoint(5, a.lat_deg, a.lon_deg, a.alt_amsl_m, 22.0, True, cmd)
        assert rejoin(FROM["lat_deg"], FROM["lon_deg"], prev, land) == []
    mid_lat, mid_lon = (a.lat_deg + land.lat_deg) / 2.0, (a.lon_deg + land.lon_deg) / 2.0
    assert rejoin(mid_lat, mid_lon, a, land) == []  # on the line
    assert rejoin(land.lat_deg + 0.001, land.lon_deg, a, land) == []  # past the leg
    near = rejoin(FROM["lat_deg"], FROM["lon_deg"], a, land)[0]
    assert not near.explicit and near.seq == 6
    assert (
        min(a.alt_amsl_m, land.alt_amsl_m) <= near.alt_amsl_m <= max(a.alt_amsl_m, land.alt_amsl_m)
    )


PAST = json.loads((DATA.parent / "arduplane_past_loiter_exit.json").read_text())


def test_a_plane_past_its_loiters_exit_is_not_sent_back_to_it() -> None:
    """Filed again by a restarted serve 700 m past its loiter's modelled exit, the soak's
    ArduPlane was planned back to that exit (UAS_OUT_OV, an auto-accepted next_waypoint)."""
    c, (run0, run1), a, land = (
        PAST["last_on_circle"], PAST["exit_run"], PAST["approach"], PAST["land"]
    )  # fmt: skip
    points = [
        NavPoint(3, c["lat_deg"], c["lon_deg"], c["alt_amsl_m"], 22.0, True, 19, amount=20.0),
        *(
            NavPoint(5, q["lat_deg"], q["lon_deg"], q["alt_amsl_m"], 22.0, True, 16).synthetic()
            for q in (run0, run1)
        ),
        NavPoint(5, a["lat_deg"], a["lon_deg"], a["alt_amsl_m"], 22.0, True, 16, landing=True),
        NavPoint(6, land["lat_deg"], land["lon_deg"], land["alt_amsl_m"], 22.0, True, 21,
                 landing=True),
    ]  # fmt: skip

    def plan(turn_from_m: float) -> list[tuple[float, float]]:
        p = plan_from_points(
            points, OperationId("sys4"), t_s=0.0, current_seq=5,
            position=Position(**PAST["filed_from"]), turn_from_m=turn_from_m,
        )  # fmt: skip
        assert p is not None
        return [_en(w.lat_deg, w.lon_deg) for w in p.waypoints]

    track = [_en(q["lat_deg"], q["lon_deg"]) for q in PAST["track"]]
    fixed_wing, multirotor = plan(80.0), plan(0.0)
    assert max(_off_m(fixed_wing, *q) for q in track) < 3.0
    # on from where it is: the plan's next point is ahead (south), not the exit 700 m back
    assert fixed_wing[1] == _en(a["lat_deg"], a["lon_deg"])
    assert multirotor[1][1] - multirotor[0][1] > 700.0
