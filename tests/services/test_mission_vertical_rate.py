"""A mission downloaded from a vehicle is what its autopilot flies: it is never refused, and
a multirotor's steep legs (take-off, landing, a climb between waypoints) are timed at its
envelope's climb and descent rates, not at its horizontal speed along the 3D leg (a 50 m
take-off at 8 m/s took 6.3 s in the plan and 17 s at the 3 m/s climb rate)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_vehicle_ops import HOME, _Info, _Key, _relative_mission, _status, _usm

from gcs_utm.model import OperationId, Position, SysId
from gcs_utm.services.mission_points import NAV_LAND, NAV_TAKEOFF, NavPoint, plan_from_points


def _point(seq: int, north_m: float, alt_m: float, command: int = 16) -> NavPoint:
    return NavPoint(seq, 40.0 + north_m / 110_540.0, -3.0, alt_m, 8.0, True, command)


def test_steep_legs_are_timed_at_the_envelopes_rates() -> None:
    points = [
        _point(0, 0.0, 650.0, NAV_TAKEOFF),  # 50 m up from the ground at 600 m
        _point(1, 80.0, 650.0),
        _point(2, 100.0, 680.0),  # 30 m up over 20 m: 36 m at 8 m/s = 4.5 s; 10 s at 3 m/s
        _point(3, 100.0, 600.0, NAV_LAND),  # 80 m down: 10 s at 8 m/s; 53.3 s at 1.5 m/s
    ]
    ground = Position(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=600.0)
    fast = plan_from_points(points, OperationId("q"), t_s=0.0, position=ground)
    plan = plan_from_points(
        points,
        OperationId("q"),
        t_s=0.0,
        position=ground,
        climb_rate_mps=3.0,
        descent_rate_mps=1.5,
    )
    assert fast is not None and plan is not None
    legs = [b.t_s - a.t_s for a, b in zip(plan.waypoints, plan.waypoints[1:], strict=False)]
    fast_legs = [b.t_s - a.t_s for a, b in zip(fast.waypoints, fast.waypoints[1:], strict=False)]
    assert fast_legs == pytest.approx([50.0 / 8.0, 80.0 / 8.0, 36.06 / 8.0, 80.0 / 8.0], abs=0.01)
    assert legs == pytest.approx([50.0 / 3.0, 80.0 / 8.0, 30.0 / 3.0, 80.0 / 1.5], abs=0.01)


async def test_a_multirotors_filed_mission_climbs_at_its_climb_rate() -> None:
    """PX4 as QGC writes it: a take-off 20 m up from home, then level legs. Filed from the
    vehicle, its take-off takes 20 / 3 s (the envelope's 3 m/s), not 20 m at cruise."""
    usm, port, _ = _usm()
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_status(1000.0, total=3, home=HOME, position=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    wps = op.plan.waypoints
    assert [round(w.alt_amsl_m, 2) for w in wps[:2]] == [32.34, 52.34]
    env = op.performance()
    assert wps[1].t_s - wps[0].t_s == pytest.approx(20.0 / env.climb_rate_mps, abs=0.01)
    assert wps[2].t_s - wps[1].t_s == pytest.approx(100.0 / op.cruise_speed_mps, rel=0.01)
