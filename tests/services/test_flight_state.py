"""Vehicle state from the vehicle's own messages (issue 31 items 2 and 3): one notion of
airborne; nothing decided for a vehicle on the ground; home after the first 3D fix, re-filed
past the tolerance and at arming; a mission before the fix filed whole once it comes."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction.context import floor_amsl
from gcs_utm.messages import FlightMode, HazardReport, VehicleStatus
from gcs_utm.model import (
    Autopilot,
    OperationId,
    OperationState,
    Position,
    SysId,
    ThreatKind,
)
from gcs_utm.services.flight_state import FlightState, Phase

sys.path.insert(0, str(Path(__file__).parent))
from test_vehicle_ops import HOME, _Info, _Key, _relative_mission, _usm


def _s(
    *,
    armed: bool = False,
    landed: bool | None = None,
    fix: int | None = 3,
    home: Position | None = HOME,
    position: Position | None = HOME,
    reboots: int = 0,
    mode: FlightMode = FlightMode.HOLD,
    seq: int | None = None,
    total: int | None = None,
    t_s: float = 1000.0,
) -> VehicleStatus:
    return VehicleStatus(
        sys_id=SysId(1),
        t_s=t_s,
        autopilot=Autopilot.PX4,
        armed=armed,
        landed=landed,
        gnss_fix_type=fix,
        home=home,
        position=position,
        reboots=reboots,
        mode=mode,
        mission_seq=seq,
        mission_total=total,
    )


def _up(m: float) -> Position:
    return replace(HOME, alt_amsl_m=HOME.alt_amsl_m + m)


def test_airborne_from_armed_and_landed_state_else_height_or_movement() -> None:
    f = FlightState()
    assert f.update(_s(fix=0, home=_up(-2.0))) == [] and f.home is None  # no fix: no home
    assert f.update(_s()) == ["fix", "home"] and f.home == HOME
    assert f.update(_s(armed=True, landed=True)) == ["armed"] and f.phase is Phase.ARMED
    assert f.update(_s(armed=True, landed=False)) == ["took_off"] and f.airborne
    assert f.update(_s(armed=True, landed=True)) == ["landed"] and f.phase is Phase.LANDED
    assert f.update(_s(armed=False, landed=True)) == ["disarmed"] and f.phase is Phase.LANDED
    # Disarmed is on the ground, whatever the landed state says.
    g = FlightState()
    g.update(_s(landed=False))
    assert not g.airborne
    # No landed state (an autopilot that sends no EXTENDED_SYS_STATE): height or movement.
    h = FlightState()
    h.update(_s(armed=True))
    assert not h.airborne and h.flying is None  # heard armed: not assumed on the ground
    h.update(_s(armed=True, position=_up(1.0)))
    assert not h.airborne  # an altitude wandering on the ground
    h.update(_s(armed=True, position=_up(3.0)))
    assert h.airborne
    rolling = FlightState()
    rolling.update(_s(armed=True))
    rolling.update(_s(armed=True, position=replace(HOME, lat_deg=HOME.lat_deg + 1e-4)))
    assert rolling.airborne  # 11 m from where it armed: moving


def test_a_reboot_starts_a_new_preflight() -> None:
    f = FlightState()
    f.update(_s(armed=True, landed=False))
    assert f.airborne and f.home == HOME
    assert f.update(_s(fix=0, reboots=1, home=None)) == ["rebooted"]
    assert f.phase is Phase.PREFLIGHT and f.home is None and not f.had_fix


async def test_hazards_of_a_vehicle_on_the_ground_are_preflight_not_threats() -> None:
    """A rebooted ArduCopter acquiring GPS on the ground got GNSS_DEGRADATION, then a
    return_home mission and AUTO, twice (issue 31.2)."""
    usm, _port, _clock = _usm()
    usm.on_vehicle(_Info(key=_Key(1)))
    seen: list[object] = []

    async def sink(threats: list[object]) -> None:
        seen.extend(threats)

    usm.attach_threat_sink(sink)  # type: ignore[arg-type]
    usm.on_status(_s(fix=0, reboots=1, home=None))
    gnss = HazardReport(
        kind=ThreatKind.GNSS_DEGRADATION, t_s=1000.0, sys_id=SysId(1), message="GNSS fix lost"
    )
    usm.on_hazard(gnss)
    await usm.drain()
    assert seen == [] and usm.counters["hazards_on_ground"] == 1
    assert any(e.kind == "preflight" for e in usm.events)
    usm.on_status(_s(armed=True, landed=False, reboots=1))  # in the air: an emergency
    usm.on_hazard(replace(gnss, t_s=1001.0))
    await usm.drain()
    assert [t.kind for t in seen] == [ThreatKind.GNSS_DEGRADATION]  # type: ignore[attr-defined]
    # Heard armed without a landed state yet (a restart of the UTM mid-flight): not gated.
    usm.on_status(_s(armed=True, reboots=2, fix=0, home=None))
    usm.on_hazard(replace(gnss, kind=ThreatKind.LACK_OF_BATTERY, t_s=1002.0))
    await usm.drain()
    assert len(seen) == 2


async def test_remote_id_of_a_vehicle_on_the_ground_is_a_preflight_finding() -> None:
    """A PX4 on the ground broadcasts Remote ID from boot, while its mission download is
    still being retried under load: "declares Remote ID but no operation is filed" was a
    REMOTE_ID_MISMATCH threat on the operator's screen before any take-off (the nuisance
    soak, issue 31). On the ground it is the pilot's pre-flight check; in the air a threat."""
    usm, _port, _clock = _usm()
    usm.on_vehicle(_Info(key=_Key(1)))
    seen: list[object] = []

    async def sink(threats: list[object]) -> None:
        seen.extend(threats)

    usm.attach_threat_sink(sink)  # type: ignore[arg-type]
    usm.on_status(_s())
    unfiled = HazardReport(
        kind=ThreatKind.REMOTE_ID_MISMATCH, t_s=1000.0, sys_id=SysId(1),
        message="sysid 1 declares Remote ID (OPEN_DRONE_ID_LOCATION) but no operation is filed",
        source="remote-id",
    )  # fmt: skip
    usm.on_hazard(unfiled)
    await usm.drain()
    assert seen == [] and usm.counters["hazards_on_ground"] == 1
    usm.on_status(_s(armed=True, landed=False))
    usm.on_hazard(replace(unfiled, t_s=1001.0))
    await usm.drain()
    assert [t.kind for t in seen] == [ThreatKind.REMOTE_ID_MISMATCH]  # type: ignore[attr-defined]


async def test_the_airspace_snapshot_says_who_is_airborne_and_the_operation_ends_on_landing() -> (
    None
):
    usm, port, _clock = _usm()
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_s(total=3))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None
    snap = usm.airspace.snapshot(1000.0, lambda: ({}, None))
    assert op.id in snap.grounded and op.id not in snap.airborne
    usm.on_status(_s(armed=True, landed=False, total=3, mode=FlightMode.MANUAL))
    snap = usm.airspace.snapshot(1001.0, lambda: ({}, None))
    assert op.id in snap.airborne
    # airborne in a manual mode is an active flight; landed and disarmed ends it
    assert usm.airspace.operation(op.id).state is OperationState.ACTIVE
    usm.on_status(_s(armed=False, landed=True, total=3))
    assert usm.airspace.operation(op.id).state is OperationState.LANDED


async def test_a_mission_before_the_first_fix_is_filed_whole_when_the_fix_comes() -> None:
    """PX4 sends HOME_POSITION before its fix; the mission was filed with its last waypoint
    only and corrected 32-53 s later (issue 31.3)."""
    usm, port, clock = _usm()
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    early_home = _up(-2.0)  # PX4's estimate before its fix
    usm.on_status(_s(fix=0, home=early_home, position=early_home, seq=2, total=3))
    await usm.drain()
    assert usm.airspace.by_sys_id(SysId(1)) is None
    clock.set(1005.0)
    usm.on_status(_s(fix=3, seq=2, total=3, t_s=1005.0))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.home == HOME
    # every waypoint (take-off and both legs), not only the last: it has not flown any
    assert [round(w.alt_amsl_m, 2) for w in op.plan.waypoints] == [32.34, 52.34, 52.34, 52.34]


async def test_home_refiled_past_the_tolerance_and_at_arming_sets_the_floor() -> None:
    """PX4's home altitude wandered 2 m; a go_down plan built on it took the quad to 8.36 m
    above PX4's home at arming (the floor is 10 m; issue 31.3)."""
    usm, port, _clock = _usm()
    port.mission = _relative_mission()
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_s(total=3))
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 1
    usm.on_status(_s(total=3, home=_up(1.5)))  # more than the 1 m tolerance
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.plan.version == 2 and op.home == _up(1.5)
    usm.on_status(_s(total=3, home=_up(1.9), armed=True, landed=True))  # 0.4 m, at arming
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(1))
    assert op is not None and op.home == _up(1.9) and op.plan.version == 3
    td = sc.build_manager().td
    assert floor_amsl(op, td.frame, td.config) == pytest.approx(HOME.alt_amsl_m + 1.9 + 10.0)


async def test_an_operation_filed_elsewhere_takes_the_vehicles_home_at_arming() -> None:
    usm, _port, _clock = _usm()
    op = replace(
        sc.make_operation("S", [(0.0, 0.0, 60.0), (100.0, 0.0, 60.0)]),
        sys_id=SysId(1),
        home=_up(-2.0),
        state=OperationState.PLANNED,
    )
    usm.airspace.add_operation(op)
    usm.on_vehicle(_Info(key=_Key(1)))
    usm.on_status(_s())
    usm.on_status(_s(armed=True, landed=True))
    await usm.drain()
    assert usm.airspace.operation(OperationId("S")).home == HOME
