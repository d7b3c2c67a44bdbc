"""EM and TD decide on the plans re-timed from each UAS's progress (``retime.py``). A UAS
holding where its plan holds (EM's "delay") is on schedule: it leaves when the hold ends. It
was taken as early or late by the time to the hold's nearer end, so a UAS 12 s into a 25 s
hold was planned around as if it left 12 s early, and the plan EM chose for another UAS
crossed its real path (enc_1_0134_merge_near_threshold: UAS5 turned into UAS2, 21 m against
50 m)."""

from __future__ import annotations

from gcs_utm.core.deconfliction.retime import retime_plan
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Operation,
    OperationId,
    Track,
    TrackId,
    VehicleKind,
    Waypoint4D,
)

FRAME = LocalFrame(40.66, -3.597, 675.0)


def _wp(e: float, n: float, t: float) -> Waypoint4D:
    lat, lon = FRAME.point_to_wgs84(e, n)
    return Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=750.0, t_s=t)


# To (10, 0) by 45 s, hold there until 70 s, then 400 m on by 170 s.
PLAN = FlightPlan(
    operation_id=OperationId("UAS2"),
    version=2,
    waypoints=(_wp(0, 0, 43.0), _wp(10, 0, 45.0), _wp(10, 0, 70.0), _wp(410, 0, 170.0)),
)
OP = Operation(
    id=OperationId("UAS2"),
    icao24=None,
    sys_id=None,
    priority=7,
    plan=PLAN,
    vehicle_kind=VehicleKind.MULTIROTOR,
    cruise_speed_mps=4.0,
    flight_geometry_m=8.0,
    operational_volume_m=15.0,
)


def _track(e: float, t: float) -> Track:
    lat, lon = FRAME.point_to_wgs84(e, 0.0)
    return Track(
        id=TrackId("UAS2"),
        t_s=t,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=750.0,
        east_m=e,
        north_m=0.0,
        vel_enu_mps=(0.0, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
    )


def test_a_uas_on_its_hold_leaves_when_the_hold_ends() -> None:
    for t in (46.0, 50.0, 58.0, 65.0, 69.0):
        plan = retime_plan(FRAME, OP, _track(10.0, t), max_offset_m=15.0)
        assert plan is not None
        times = [w.t_s for w in plan.waypoints]
        assert times == [t, 70.0, 170.0], t


def test_a_uas_still_at_its_hold_after_it_ends_is_late() -> None:
    plan = retime_plan(FRAME, OP, _track(10.0, 75.0), max_offset_m=15.0)
    assert plan is not None
    times = [w.t_s for w in plan.waypoints]
    assert times[0] == 75.0
    assert times[-1] == 175.0
