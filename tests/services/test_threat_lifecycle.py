"""Threats raised from hazards close when their cause is gone (issue 31, threat lifecycle):
link loss when positions flow again, GNSS degradation when the fix is back, any UAS threat
when the vehicle is on the ground, a sysid claim when the other sender is quiet; the reason is
audited and on the closed threat, and the same hazard later is a new threat."""

from __future__ import annotations

import sys
from pathlib import Path

from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, HazardReport, VehicleStatus
from gcs_utm.model import (
    AuditEntry,
    Autopilot,
    OperationId,
    OperationState,
    SysId,
    Threat,
    ThreatKind,
    ThreatStatus,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm, UsmConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import OP, make_operation

T0 = 1000.0


def _usm() -> tuple[Usm, ManualClock, list[object], dict[OperationId, float]]:
    clock = ManualClock(T0)
    airspace = Airspace()
    airspace.load([make_operation(T0)], [])
    recorded: list[object] = []
    usm = Usm(airspace, clock, record=recorded.append, config=UsmConfig(threat_clear_s=2.0))
    positions: dict[OperationId, float] = {}
    usm.attach_threat_evidence(positions.get, fresh_s=5.0, eph_good_m=5.0)
    return usm, clock, recorded, positions


def _status(t_s: float, **kw: object) -> VehicleStatus:
    base: dict[str, object] = dict(
        sys_id=SysId(1), t_s=t_s, autopilot=Autopilot.PX4, mode=FlightMode.MISSION, armed=True
    )
    base.update(kw)
    return VehicleStatus(**base)  # type: ignore[arg-type]


async def _tick(usm: Usm, clock: ManualClock, dt_s: float) -> None:
    clock.advance(dt_s)
    await usm.threat_closer.check(clock.now_s())
    await usm.drain()


def _closed(recorded: list[object]) -> list[Threat]:
    return [t for t in recorded if isinstance(t, Threat) and t.status is ThreatStatus.CLOSED]


def _reasons(recorded: list[object]) -> list[str]:
    return [
        str(a.detail["reason"])
        for a in recorded
        if isinstance(a, AuditEntry) and a.action == "threat_closed"
    ]


async def test_link_loss_closes_when_positions_flow_again_and_can_open_again() -> None:
    usm, clock, recorded, positions = _usm()
    positions[OP] = T0 - 6.0
    usm.on_hazard(
        HazardReport(kind=ThreatKind.COMMUNICATION_FAILURE, t_s=T0, operation_id=OP, source="t")
    )
    await usm.drain()
    (tid,) = usm.threats
    await _tick(usm, clock, 5.0)
    assert tid in usm.threats  # still no position: open
    positions[OP] = clock.now_s()  # the vehicle is back (a reboot, a link restored)
    await _tick(usm, clock, 1.0)
    positions[OP] = clock.now_s()
    await _tick(usm, clock, 1.5)
    assert tid in usm.threats  # gone for 1.5 s of the 2 s it must be gone
    await _tick(usm, clock, 0.5)
    assert tid not in usm.threats and usm.threat_closer.watching() == {}
    (closed,) = _closed(recorded)
    assert closed.id == tid and "positions of UAS1 flow again" in closed.message
    assert any("flow again" in r for r in _reasons(recorded))
    assert any(e.kind == "threat" and "closed" in e.text for e in usm.events)
    # the same hazard within the coalescing cooldown is a new threat, not swallowed
    usm.on_hazard(
        HazardReport(
            kind=ThreatKind.COMMUNICATION_FAILURE, t_s=clock.now_s(), operation_id=OP, source="t"
        )
    )
    await usm.drain()
    assert len(usm.threats) == 1 and tid not in usm.threats


async def test_a_flapping_link_does_not_close_it() -> None:
    usm, clock, recorded, positions = _usm()
    usm.on_hazard(HazardReport(kind=ThreatKind.COMMUNICATION_FAILURE, t_s=T0, operation_id=OP))
    await usm.drain()
    positions[OP] = T0 + 0.5  # one frame, then silence again
    for _ in range(10):
        await _tick(usm, clock, 1.0)
    assert len(usm.threats) == 1 and _closed(recorded) == []


async def test_gnss_degradation_closes_when_the_fix_is_back() -> None:
    usm, clock, recorded, _ = _usm()
    usm.on_hazard(HazardReport(kind=ThreatKind.GNSS_DEGRADATION, t_s=T0, sys_id=SysId(1)))
    await usm.drain()
    usm.on_status(_status(T0 + 1.0, gnss_fix_type=3, eph_m=12.0))  # a fix, still poor
    for _ in range(4):
        await _tick(usm, clock, 1.0)
    assert len(usm.threats) == 1
    usm.on_status(_status(T0 + 5.0, gnss_fix_type=3, eph_m=1.2))
    for _ in range(4):
        await _tick(usm, clock, 1.0)
    assert usm.threats == {}
    assert _reasons(recorded) == ["GNSS fix back (fix_type 3, accuracy 1.2 m)"]


async def test_any_uas_threat_closes_on_the_ground_and_a_claim_when_quiet() -> None:
    usm, clock, recorded, _ = _usm()
    usm.on_hazard(HazardReport(kind=ThreatKind.LACK_OF_BATTERY, t_s=T0, sys_id=SysId(1)))
    usm.on_hazard(HazardReport(kind=ThreatKind.SYSID_CONFLICT, t_s=T0, sys_id=SysId(1)))
    await usm.drain()
    usm.on_status(_status(T0 + 1.0))  # armed, flying
    for k in range(20):  # the impostor goes on claiming for 20 s
        usm.on_hazard(
            HazardReport(kind=ThreatKind.SYSID_CONFLICT, t_s=clock.now_s(), sys_id=SysId(1))
        )
        await _tick(usm, clock, 1.0)
        assert len(usm.threats) == 2, k
    usm.on_status(_status(clock.now_s(), armed=False, landed=True))
    for _ in range(3):
        await _tick(usm, clock, 1.0)
    # on the ground: both close (a UAS on the ground has no battery or sysid emergency)
    assert usm.threats == {}
    # (the flight state may say "landed" before or after the lifecycle sees the disarm)
    on_ground = {"operation UAS1 landed", "UAS1 is on the ground (disarmed)"}
    reasons = _reasons(recorded)
    assert len(reasons) == 2 and set(reasons) <= on_ground, reasons


async def test_a_claim_closes_when_the_other_sender_is_quiet() -> None:
    usm, clock, recorded, _ = _usm()
    usm.on_hazard(HazardReport(kind=ThreatKind.SYSID_CONFLICT, t_s=T0, sys_id=SysId(1)))
    await usm.drain()
    for _ in range(31):
        await _tick(usm, clock, 1.0)
    assert len(usm.threats) == 1  # 30 s cooldown + 2 s clear
    for _ in range(3):
        await _tick(usm, clock, 1.0)
    assert usm.threats == {}
    assert _reasons(recorded) == ["no other sender claimed the system id for 30 s"]


async def test_a_disarmed_vehicle_of_a_planned_operation_is_on_the_ground() -> None:
    """ArduPilot reports no landed state: disarmed, not reported airborne, is on the ground."""
    usm, clock, recorded, _ = _usm()
    usm.on_hazard(HazardReport(kind=ThreatKind.TECHNICAL_FAILURE, t_s=T0, sys_id=SysId(1)))
    await usm.drain()
    usm.on_status(_status(T0 - 1.0, armed=False))  # older than the threat: no evidence
    for _ in range(4):
        await _tick(usm, clock, 1.0)
    assert len(usm.threats) == 1
    usm.on_status(_status(T0 + 5.0, armed=False, landed=None, mode=FlightMode.HOLD))
    for _ in range(4):
        await _tick(usm, clock, 1.0)
    assert usm.threats == {}
    assert _reasons(recorded) == ["UAS1 is on the ground (disarmed)"]


async def test_link_loss_of_an_ended_operation_closes_without_positions() -> None:
    """A flight that ended sends no more positions: its link loss (raised when its track went
    stale after the end) closes on the end alone; it stayed open for ever before (the soak)."""
    usm, clock, recorded, positions = _usm()
    positions[OP] = T0 - 6.0
    usm.on_hazard(
        HazardReport(kind=ThreatKind.COMMUNICATION_FAILURE, t_s=T0, operation_id=OP, source="t")
    )
    await usm.drain()
    (tid,) = usm.threats
    usm.airspace.set_state(OP, OperationState.ENDED)
    for _ in range(4):
        await _tick(usm, clock, 1.0)
    assert tid not in usm.threat_closer.watching()
    assert [t.id for t in _closed(recorded)] == [tid]
    assert _reasons(recorded) == [f"operation {OP} ended"]
