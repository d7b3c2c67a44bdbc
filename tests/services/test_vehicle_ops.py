"""Operations from vehicles (gcs_utm.services.vehicle_ops): filed and re-filed as the
vehicle's mission changes, home from HOME_POSITION (never the first altitude), timed from the
vehicle's progress, the ground warning. The USM with a fake MAVLink side on a manual clock."""

from __future__ import annotations

import asyncio
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, PilotAnswer, PilotDecision, VehicleStatus
from gcs_utm.model import (
    Alternative,
    Autopilot,
    FlightPlan,
    Maneuver,
    OperationId,
    Position,
    Recommendation,
    RecommendationId,
    SysId,
    ThreatId,
    ThreatKind,
    VehicleKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mission_points import mission_is_plan, mission_points, plan_from_points
from gcs_utm.services.usm import Usm
from gcs_utm.services.vehicle_ops import CONOPS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import FakeVehicles, Result, make_operation

HOME = Position(lat_deg=45.4671160, lon_deg=-73.7578370, alt_amsl_m=32.34)
NORTH_100M_E7 = 9046  # ~100.0 m of latitude, in degrees x 1e7


@dataclass
class _Item:
    command: int
    x: int = 0
    y: int = 0
    z: float = 0.0
    frame: int = 0
    param2: float = 0.0
    seq: int = 0


@dataclass
class _Key:
    sys_id: int


@dataclass
class _Info:
    key: _Key
    autopilot: Autopilot = Autopilot.PX4
    vehicle_kind: VehicleKind = VehicleKind.MULTIROTOR


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def _relative_mission(alt_m: float = 20.0, legs: int = 2) -> list[_Item]:
    """PX4 as QGC writes it: takeoff, then waypoints in MAV_FRAME_GLOBAL_RELATIVE_ALT_INT."""
    lat, lon = _e7(HOME.lat_deg), _e7(HOME.lon_deg)
    items = [_Item(command=22, x=lat, y=lon, z=alt_m, frame=6, seq=0)]
    for k in range(1, legs + 1):
        items.append(_Item(command=16, x=lat + k * NORTH_100M_E7, y=lon, z=alt_m, frame=6, seq=k))
    return items


class _Port(FakeVehicles):
    def __init__(self) -> None:
        super().__init__()
        self.mission: list[_Item] = []
        self.downloads = 0

    async def download_mission(self, sys_id: SysId) -> list[_Item]:
        self.downloads += 1
        return list(self.mission)


def _usm(ground: float | None = None, clock_t: float = 1000.0) -> tuple[Usm, _Port, ManualClock]:
    clock = ManualClock(clock_t)
    usm = Usm(Airspace(), clock, ground_elevation_amsl_m=ground)
    port = _Port()
    usm.attach_vehicles(port)
    return usm, port, clock


def _status(
    t_s: float,
    *,
    total: int | None = None,
    mission_id: int | None = None,
    home: Position | None = None,
    position: Position | None = None,
    armed: bool = False,
    mode: FlightMode = FlightMode.HOLD,
    seq: int | None = None,
    fix: int | None = 3,
    landed: bool | None = None,
    reboots: int = 0,
) -> VehicleStatus:
    return VehicleStatus(
        sys_id=SysId(1),
        t_s=t_s,
        autopilot=Autopilot.PX4,
        mode=mode,
        armed=armed,
        mission_seq=seq,
        mission_total=total,
        home=home,
        mission_id=mission_id,
        position=position,
        gnss_fix_type=fix,
        landed=landed,
        reboots=reboots,
    )


def test_mission_points_relative_to_home_and_takeoff_here() -> None:
    items = [
        _Item(command=22, z=10.0, frame=3),  # takeoff "here": at home
        _Item(command=16, x=400000000, y=-30000000, z=20.0, frame=3, seq=1),
        _Item(command=178, param2=10.0, frame=2, seq=2),
        _Item(command=16, x=400009000, y=-30000000, z=20.0, frame=3, seq=3),  # ~99.5 m north
        _Item(command=21, frame=3, seq=4),  # land at the previous position
    ]
    home = Position(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=600.0)
    assert mission_points(items, home=None, cruise_speed_mps=5.0) is None  # waits for home
    points = mission_points(items, home=home, cruise_speed_mps=5.0)
    assert points is not None
    assert [p.alt_amsl_m for p in points] == [610.0, 620.0, 620.0, 600.0]
    assert [p.speed_mps for p in points] == [5.0, 5.0, 10.0, 10.0]
    plan = plan_from_points(points, OperationId("x"), t_s=100.0)
    assert plan is not None
    assert plan.waypoints[2].t_s - plan.waypoints[1].t_s == pytest.approx(99.486 / 10.0, abs=0.01)
    assert mission_is_plan(points, plan)
    # timed from the current item and the vehicle's position, not from the first item
    at = Position(lat_deg=40.0004, lon_deg=-3.0, alt_amsl_m=620.0)
    later = plan_from_points(points, OperationId("x"), t_s=500.0, current_seq=3, position=at)
    assert later is not None and len(later.waypoints) == 3
    assert later.waypoints[0].t_s == 500.0 and later.waypoints[0].lat_deg == 40.0004
    assert later.waypoints[1].t_s == pytest.approx(500.0 + 55.3 / 10.0, abs=0.1)


async def test_mission_before_the_fix_waits_for_home_then_is_filed() -> None:
    """PX4 with a mission before its first fix: no home, relative altitudes. Used to be
    'no waypoints in its mission: no operation' (issue 18.4)."""
    usm, port, clock = _usm()
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    await usm.drain()
    assert usm.airspace.by_sys_id(SysId(1)) is None
    assert any("has not reported yet" in e.text for e in usm.events)
    clock.set(1010.0)
    usm.on_status(_status(1010.0, total=3, home=HOME, position=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.conops == CONOPS and op.home == HOME
    assert [round(w.alt_amsl_m, 2) for w in op.plan.waypoints] == [32.34, 52.34, 52.34, 52.34]
    assert op.plan.waypoints[0].t_s == 1010.0  # timed from now, not the download
    assert not any("no waypoints" in e.text for e in usm.events)


async def test_failed_download_at_discovery_is_retried_with_backoff() -> None:
    """PX4 under load times out the discovery download ("Operation timeout"): the mission is
    downloaded again after a backoff on the vehicle's next status, not only when the mission
    changes (it never changes: the vehicle would otherwise stay without an operation)."""
    usm, port, clock = _usm()
    port.mission = _relative_mission()
    failures = [TimeoutError("no MISSION_COUNT"), TimeoutError("no MISSION_COUNT")]
    plain = port.download_mission

    async def flaky(sys_id: SysId) -> list[_Item]:
        if failures:
            port.downloads += 1
            raise failures.pop(0)
        return await plain(sys_id)

    port.download_mission = flaky  # type: ignore[method-assign]
    usm.attach_vehicles(port)
    status = dict(total=3, home=HOME, position=HOME)
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_status(1000.0, **status))  # type: ignore[arg-type]  # count known at start
    await usm.drain()
    usm.on_status(_status(1000.5, **status))  # type: ignore[arg-type]
    await usm.drain()
    assert port.downloads == 1  # backoff: not yet
    clock.set(1002.0)
    usm.on_status(_status(1002.0, **status))  # type: ignore[arg-type]
    await usm.drain()
    assert port.downloads == 2 and usm.airspace.by_sys_id(SysId(1)) is None
    clock.set(1005.0)
    usm.on_status(_status(1005.0, **status))  # type: ignore[arg-type]
    await usm.drain()
    assert port.downloads == 2  # the second failure doubled the wait to 4 s
    clock.set(1006.0)
    usm.on_status(_status(1006.0, **status))  # type: ignore[arg-type]
    await usm.drain()
    assert port.downloads == 3
    assert usm.airspace.by_sys_id(SysId(1)) is not None
    assert sum("mission download failed" in e.text for e in usm.events) == 2
    usm.on_status(_status(1100.0, **status))  # type: ignore[arg-type]
    await usm.drain()
    assert port.downloads == 3  # a success ends the retries


async def test_connected_airborne_altitudes_from_home_not_first_altitude() -> None:
    """An ArduCopter found airborne 40 m up: waypoints relative to its home (mission item 0,
    then HOME_POSITION), not to the first altitude it reports (issue 26.4)."""
    usm, port, clock = _usm()
    home_item = _Item(command=16, x=_e7(HOME.lat_deg), y=_e7(HOME.lon_deg), z=32.34, frame=0)
    port.mission = [home_item, *_relative_mission()[1:]]
    for k, it in enumerate(port.mission):
        it.seq = k
    airborne = Position(lat_deg=HOME.lat_deg, lon_deg=HOME.lon_deg, alt_amsl_m=72.3)
    usm.on_vehicle(_Info(key=_Key(1), autopilot=Autopilot.ARDUPILOT))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.home == HOME
    assert [round(w.alt_amsl_m, 2) for w in op.plan.waypoints] == [52.34, 52.34]
    usm.on_status(_status(clock.now_s(), total=2, position=airborne, home=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 1  # same home, same mission: nothing new


async def test_mission_uploaded_after_discovery_is_filed_and_changes_refile() -> None:
    """No mission at discovery, one uploaded later (issue 18.4: 0 operations), then another:
    a new plan version each time; a status that repeats the same mission changes nothing."""
    usm, port, clock = _usm()
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_status(1000.0, total=0, home=HOME, position=HOME))
    await usm.drain()
    assert usm.airspace.by_sys_id(SysId(1)) is None and port.downloads == 1
    port.mission = _relative_mission(legs=2)
    clock.set(1005.0)
    usm.on_status(_status(1005.0, total=3, home=HOME, position=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 1 and len(op.plan.waypoints) == 4
    usm.on_status(_status(1006.0, total=3, home=HOME, position=HOME))
    await usm.drain()
    assert port.downloads == 2
    # same length, new opaque id (PX4): downloaded and re-filed
    port.mission = _relative_mission(alt_m=35.0, legs=2)
    usm.on_status(_status(1007.0, total=3, mission_id=77, home=HOME, position=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 2 and op.plan.waypoints[-1].alt_amsl_m == 67.34
    # the UTM uploads its own plan: the mission is the plan, nothing re-filed
    assert mission_is_plan(
        mission_points(port.mission, home=HOME, cruise_speed_mps=5.0) or [], op.plan
    )
    usm.on_status(_status(1008.0, total=3, mission_id=78, home=HOME, position=HOME))
    await usm.drain()
    assert usm.airspace.by_sys_id(SysId(1)).plan.version == 2  # type: ignore[union-attr]
    assert usm.vehicle_ops.counters["refiled"] == 1


async def test_operation_filed_elsewhere_stands_until_the_mission_changes() -> None:
    """A scenario's operation for sysid 1: the vehicle's mission at discovery does not
    replace it; a mission changed later (not the plan) is a new plan version."""
    usm, port, _clock = _usm()
    op0 = make_operation(1000.0)
    usm.airspace.load([op0], [])
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_status(1000.0, total=3, home=HOME, position=HOME))
    await usm.drain()
    assert usm.airspace.by_sys_id(SysId(1)) == op0
    port.mission = _relative_mission(legs=3)
    usm.on_status(_status(1001.0, total=4, home=HOME, position=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.id == op0.id and op.plan.version == 2
    assert op.conops == op0.conops  # still the scenario's operation


async def test_home_moves_refile_and_plan_retimed_when_the_mission_starts() -> None:
    usm, port, clock = _usm()
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_status(1000.0, total=3, home=HOME, position=HOME))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 1
    moved = Position(lat_deg=HOME.lat_deg, lon_deg=HOME.lon_deg, alt_amsl_m=40.0)
    usm.on_status(_status(1001.0, total=3, home=moved, position=moved))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 2 and op.home == moved
    assert op.plan.waypoints[-1].alt_amsl_m == pytest.approx(60.0)
    # 60 s on the ground, then armed in mission mode: re-timed from now
    clock.set(1060.0)
    usm.on_status(
        _status(
            1060.0, total=3, home=moved, position=moved, armed=True, mode=FlightMode.MISSION, seq=0
        )
    )
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.waypoints[0].t_s == 1060.0
    assert usm.vehicle_ops.counters["retimed"] == 1
    # a new current item on time: no new version; 30 s late: re-timed
    v = op.plan.version
    wp1 = op.plan.waypoints[2]
    at = Position(lat_deg=wp1.lat_deg, lon_deg=wp1.lon_deg, alt_amsl_m=wp1.alt_amsl_m)
    clock.set(wp1.t_s)
    usm.on_status(
        _status(
            wp1.t_s, total=3, home=moved, position=at, armed=True, mode=FlightMode.MISSION, seq=2
        )
    )
    assert usm.airspace.by_sys_id(SysId(1)).plan.version == v  # type: ignore[union-attr]
    clock.set(wp1.t_s + 30.0)
    usm.on_status(
        _status(
            wp1.t_s + 30,
            total=3,
            home=moved,
            position=at,
            armed=True,
            mode=FlightMode.MISSION,
            seq=1,
        )
    )
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == v + 1


@pytest.mark.parametrize(("ground", "warned"), [(488.0, True), (40.0, False), (None, False)])
async def test_home_far_from_the_airspace_ground_warns_once(
    ground: float | None, warned: bool
) -> None:
    usm, _port, _clock = _usm(ground=ground)
    usm.on_vehicle(_Info(key=_Key(1)))
    for t in (1000.0, 1001.0):
        usm.on_status(_status(t, home=HOME))
    usm.on_status(_status(1002.0, home=Position(lat_deg=45.5, lon_deg=-73.7, alt_amsl_m=30.0)))
    await usm.drain()
    warnings = [e.text for e in usm.events if e.kind == "warning"]
    assert len(warnings) == int(warned)
    if warned:
        assert "32.34" in warnings[0] and "488.00" in warnings[0]


def _items_of(plan: FlightPlan) -> list[_Item]:
    """The plan as a mission in MAV_FRAME_GLOBAL (AMSL), as the USM uploads it."""
    return [
        _Item(command=16, x=_e7(w.lat_deg), y=_e7(w.lon_deg), z=w.alt_amsl_m, frame=0, seq=k)
        for k, w in enumerate(plan.waypoints)
    ]


async def test_the_echo_of_the_usms_own_upload_is_not_filed_as_the_pilots_mission() -> None:
    """The upload changes the vehicle's mission, which starts a download; when that download
    ended before the readback did, the uploaded plan was filed "from the vehicle's mission"
    under the next version and the recommendation's own plan was then refused ("plan version
    2 is not newer than 2"; seen in use case 2): the UTM held a copy timed from the download,
    not the plan EM made."""
    usm: Usm
    op0 = make_operation(100.0)

    class EchoPort(_Port):
        async def upload_plan(self, sys_id: SysId, plan: FlightPlan, **kw: object) -> Result:
            self.mission = _items_of(plan)  # the vehicle has the new mission...
            usm.on_status(_status(112.0, total=len(self.mission), mission_id=9, home=HOME))
            for _ in range(10):  # ...and the download of it ends before the readback
                await asyncio.sleep(0)
            return await super().upload_plan(sys_id, plan, **kw)  # type: ignore[arg-type]

    clock = ManualClock(110.0)
    usm = Usm(Airspace(), clock)
    usm.airspace.load([op0], [])
    port = EchoPort()
    port.mission = _items_of(op0.plan)
    usm.attach_vehicles(port)
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_status(110.0, total=2, mission_id=8, home=HOME, position=HOME))
    await usm.drain()
    up = tuple(dataclasses.replace(w, alt_amsl_m=720.0) for w in op0.plan.waypoints)
    new = dataclasses.replace(op0.plan, waypoints=up)
    rec = Recommendation(
        id=RecommendationId("t1/UAS1"),
        version=1,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=op0.id,
        created_t_s=110.0,
        deadline_t_s=130.0,
        selected=Alternative(
            operation_id=op0.id, maneuver=Maneuver.GO_UP, plan=new, cost=0.1, risk=0.1
        ),
    )
    await usm.on_recommendation(rec)
    answer = PilotAnswer(
        recommendation_id=rec.id, version=1, decision=PilotDecision.ACCEPT, t_s=111.0,
        operator="alice", source="dashboard",
    )  # fmt: skip
    await usm.answer(answer)
    await usm.drain()
    assert port.downloads >= 2  # the echo was downloaded
    op = usm.airspace.operation(op0.id)
    assert (op.plan.version, op.plan.reason) == (2, "LOSS_OF_SEPARATION: go_up")
    assert usm.vehicle_ops.counters["refiled"] == 0
