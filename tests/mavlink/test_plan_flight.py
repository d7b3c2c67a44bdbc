"""A 4D plan turned into a mission (``plan_to_mission_items``) and flown by the sitl multirotor
keeps the plan's times and altitudes: use case 1's go-down manoeuvre (climb on the spot, a
slower climb, then a long descending leg across the power line). Stepping a Vehicle directly,
no sockets."""

from __future__ import annotations

import itertools
import math

import pytest

import sitl
from adapters.mavlink import plan_to_mission_items
from adapters.mavlink.mission import MAV_CMD_NAV_WAYPOINT, MissionItem
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, OperationId, Waypoint4D
from sitl.mission import RawItem
from sitl.vehicle import Vehicle

HOME = (40.65974645776713, -3.59689676974471, 675.0)
FRAME = LocalFrame(HOME[0], HOME[1])
A = (340.0, 0.0)  # east, north of the corner where use case 1's M600 climbs


def _wp(east: float, north: float, agl: float, t: float) -> Waypoint4D:
    lat, lon = FRAME.point_to_wgs84(east, north)
    return Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=HOME[2] + agl, t_s=t)


# use case 1's go-down plan as TD produced it (report plan version 2, times from its start):
# climb 32 m on the spot at the 2 m/s limit, 2.15 m in 2 s, 7.25 m in 9.07 s (slower than the
# limit: the rest is a wait), then 109 m north at 3.3 m/s descending 39.5 m, then 31 m up 11.4.
GO_DOWN = FlightPlan(
    operation_id=OperationId("UAS1"),
    version=2,
    waypoints=(
        _wp(*A, 45.87, 0.0),
        _wp(*A, 77.87, 16.0),
        _wp(*A, 80.02, 18.0),
        _wp(*A, 87.27, 27.067),
        _wp(A[0], 109.0, 47.75, 60.0),
        _wp(A[0], 140.0, 59.14, 69.49),
    ),
)


def _raw(it: MissionItem) -> RawItem:
    return RawItem(
        it.seq,
        it.frame,
        it.command,
        it.current,
        it.autocontinue,
        it.param1,
        it.param2,
        it.param3,
        it.param4,
        it.x,
        it.y,
        it.z,
    )


def _plan_at(plan: FlightPlan, t: float) -> tuple[float, float, float]:
    wps = plan.waypoints
    t = min(max(t, wps[0].t_s), wps[-1].t_s)
    for a, b in itertools.pairwise(wps):
        if a.t_s <= t <= b.t_s:
            u = (t - a.t_s) / (b.t_s - a.t_s)
            ea, na = FRAME.point_to_local(a.lat_deg, a.lon_deg)
            eb, nb = FRAME.point_to_local(b.lat_deg, b.lon_deg)
            return (
                ea + u * (eb - ea),
                na + u * (nb - na),
                a.alt_amsl_m + u * (b.alt_amsl_m - a.alt_amsl_m),
            )
    raise AssertionError(t)


def _fly(items: list[MissionItem], *, t_end: float) -> list[tuple[float, float, float, float]]:
    """The M600 of use case 1 (3.3 m/s, 2 m/s climb) hovering at the plan's first point in
    MISSION mode gets ``items`` at t = 0 (flagged current as uploaded) and flies them."""
    start = GO_DOWN.waypoints[0]
    spec = sitl.VehicleSpec(
        instance=0,
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_amsl_m=HOME[2],
        cruise_speed_mps=3.3,
        max_speed_mps=5.0,
        climb_rate_mps=2.0,
        mission=(
            sitl.MissionItemSpec(
                lat_deg=start.lat_deg, lon_deg=start.lon_deg, alt_amsl_m=start.alt_amsl_m
            ),
        ),
        auto_start_at_s=0.0,
        start_airborne=True,
    )
    v = Vehicle(spec, sitl.SimTime(start_utc_s=1_700_000_000.0))
    t = 0.0
    while t < 5.0:  # placed at the point, mission of one waypoint complete: hovering there
        t += 0.5
        v.advance(t)
    assert v.mode == "MISSION" and not v.landed
    cur = next((i.seq for i in items if i.current), None)
    v.accept_mission([_raw(i) for i in items], cur)
    out = []
    t0 = t
    while t < t0 + t_end:
        t += 0.25
        v.advance(t)
        e, n = FRAME.point_to_local(v.lat_deg, v.lon_deg)
        out.append((t - t0, e, n, v.alt_amsl_m))
    return out


def test_climb_on_the_spot_is_not_a_wait_before_it() -> None:
    items = plan_to_mission_items(GO_DOWN, climb_rate_mps=2.0, descent_rate_mps=2.0)
    wps = [i for i in items if i.command == MAV_CMD_NAV_WAYPOINT]
    assert [round(i.z - HOME[2], 2) for i in wps] == [45.87, 77.87, 80.02, 87.27, 47.75, 59.14]
    # the 16 s climb at the limit waits nowhere; the slower climbs wait what the plan leaves
    # beyond |dz| / 2 m/s, at their top (the old encoding held 16 s at the bottom, then climbed)
    assert [i.param1 for i in wps] == pytest.approx(
        [0.0, 0.0, 2.0 - 2.15 / 2.0, 9.067 - 7.25 / 2.0, 0.0, 0.0], abs=0.01
    )
    # no vehicle rate known: the plan's climb time is taken as flying time, never a prior wait
    assert all(i.param1 == 0.0 for i in plan_to_mission_items(GO_DOWN) if i.command == 16)


def test_a_wait_on_the_spot_is_still_held_where_it_is() -> None:
    wait = FlightPlan(
        operation_id=OperationId("w"),
        version=1,
        waypoints=(_wp(0, 0, 40, 0.0), _wp(0, 0, 40, 12.0), _wp(0, 50, 40, 22.0)),
    )
    items = plan_to_mission_items(wait, climb_rate_mps=2.0)
    assert [(i.command, i.param1) for i in items][:1] == [(16, 12.0)]
    assert items[1].command == 178 and items[1].param2 == pytest.approx(5.0, abs=0.05)


def test_sitl_multirotor_flies_the_go_down_plan_on_time() -> None:
    items = plan_to_mission_items(GO_DOWN, climb_rate_mps=2.0, descent_rate_mps=2.0)
    flown = _fly(items, t_end=75.0)
    at = {round(t, 2): (e, n, alt) for t, e, n, alt in flown}
    for w in GO_DOWN.waypoints[1:]:
        e, n, alt = at[round(round(w.t_s * 4) / 4, 2)]
        pe, pn, palt = _plan_at(GO_DOWN, round(w.t_s * 4) / 4)
        # at every plan time: within the 1.5 m altitude acceptance and a braking distance
        assert abs(alt - palt) < 1.5, (w.t_s, alt - HOME[2], palt - HOME[2])
        assert math.hypot(e - pe, n - pn) < 2.0, (w.t_s, n, pn)
    # in between, never further from the plan than the vertical step it is flying: a climb
    # slower than the vehicle's limit is flown at the limit, then waited at its top
    worst = max(abs(alt - _plan_at(GO_DOWN, t)[2]) for t, _e, _n, alt in flown if t <= 69.0)
    assert worst < 87.27 - 80.02, worst
    # at the power line crossing (north 65 m) the M600 is where the plan puts it
    t_x, _, _, alt_x = next(p for p in flown if p[2] >= 65.0)
    t_plan = next(t / 10 for t in range(0, 700) if _plan_at(GO_DOWN, t / 10)[1] >= 65.0)
    assert abs(t_x - t_plan) < 2.0, (t_x, t_plan)
    assert abs(alt_x - (HOME[2] + 63.6)) < 2.0, alt_x - HOME[2]


def test_sitl_multirotor_flies_the_straight_3d_line() -> None:
    """PX4 points the velocity at the waypoint in 3D and scales it within the horizontal and
    vertical limits: on a descending leg it does not drop to the new altitude first."""
    items = plan_to_mission_items(GO_DOWN, climb_rate_mps=2.0, descent_rate_mps=2.0)
    flown = _fly(items, t_end=75.0)
    n0 = A[1]
    for _t, _e, n, alt in flown:
        if 10.0 <= n <= 100.0:  # on the descending leg, away from its ends
            line_alt = HOME[2] + 87.27 + (47.75 - 87.27) * (n - n0) / 109.0
            assert abs(alt - line_alt) < 2.0, (n, alt - HOME[2], line_alt - HOME[2])
