"""DO_JUMP loops filed as flown (issue 31.6): a looping mission was filed as its listed
waypoints only."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.model import OperationId, Position
from gcs_utm.services.mission_order import flown_order
from gcs_utm.services.mission_points import mission_points, plan_from_points

HOME = Position(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=600.0)


@dataclass
class _Item:
    seq: int
    command: int
    x: int = 0
    y: int = 0
    z: float = 20.0
    frame: int = 3
    param1: float = 0.0
    param2: float = 0.0


def _wp(seq: int, north_e7: int) -> _Item:
    return _Item(seq, 16, x=400000000 + north_e7, y=-30000000)


def _looping(repeats: float) -> list[_Item]:
    """A, B, DO_JUMP to A (``repeats`` more times), C."""
    return [_wp(0, 0), _wp(1, 9000), _Item(2, 177, param1=0.0, param2=repeats), _wp(3, 18000)]


def test_a_loop_is_filed_as_flown() -> None:
    points = mission_points(_looping(2.0), home=HOME, cruise_speed_mps=10.0)
    assert points is not None
    assert [p.seq for p in points] == [0, 1, 0, 1, 0, 1, 3]
    plan = plan_from_points(points, OperationId("x"), t_s=0.0)
    assert plan is not None and len(plan.waypoints) == 7
    # ~99.5 m legs at 10 m/s: A-B, B-A twice each, then B-C
    assert plan.waypoints[-1].t_s > 6 * 9.9
    # timed from the current item: the first pass at or after it
    later = plan_from_points(points, OperationId("x"), t_s=0.0, current_seq=1)
    assert later is not None and len(later.waypoints) == 6


def test_a_loop_forever_is_bounded_and_no_jump_is_the_list() -> None:
    assert len(flown_order(_looping(-1.0))) == 500
    plain = [_wp(0, 0), _wp(1, 9000)]
    assert [i for i, _ in flown_order(plain)] == [0, 1]
    assert [i for i, _ in flown_order(_looping(0.0))] == [0, 1, 2, 3]
