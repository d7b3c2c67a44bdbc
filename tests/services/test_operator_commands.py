"""The USM's one entry point for operator commands (``Usm.operator_command``), with a recording
vehicle port: every reason to refuse (audited, nothing sent), the command EM's path sends,
verification from the reported mode, repeated request ids, and the line parser."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import OP, FakeVehicles, make_operation

from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, LinkHealth, VehicleStatus
from gcs_utm.model import AuditEntry, Autopilot, CommandKind, SysId, VehicleKind
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.operator_commands import parse_command_line
from gcs_utm.services.usm import Usm

T0 = 1000.0
FLYING = VehicleStatus(
    sys_id=SysId(1),
    t_s=T0,
    autopilot=Autopilot.PX4,
    vehicle_kind=VehicleKind.MULTIROTOR,
    mode=FlightMode.MISSION,
    armed=True,
    landed=False,
    mission_total=5,
)


class ModeVehicles(FakeVehicles):
    """Acknowledges a command and (when ``follow``) reports the commanded mode at once."""

    def __init__(self, usm: Usm, *, follow: bool = True, **kw: bool) -> None:
        super().__init__(**kw)
        self.usm, self.follow = usm, follow

    async def send_command(self, sys_id: SysId, command: object) -> object:
        result = await super().send_command(sys_id, command)  # type: ignore[arg-type]
        kind = getattr(command, "kind", None)
        mode = {
            CommandKind.HOLD: FlightMode.HOLD,
            CommandKind.RTL: FlightMode.RTL,
            CommandKind.LAND: FlightMode.LAND,
            CommandKind.RESUME: FlightMode.MISSION,
        }[kind]
        if self.follow and self.command_ok:
            old = self.usm.statuses_by_sys_id()[sys_id]
            self.usm.on_status(replace(old, mode=mode, t_s=self.usm.clock.now_s()))
        return result


def _usm(status: VehicleStatus | None = FLYING, **kw: bool) -> tuple[Usm, ModeVehicles, list]:
    records: list[object] = []
    clock = ManualClock(T0)
    airspace = Airspace()
    airspace.load([make_operation(T0, operator="alice")], ())
    usm = Usm(airspace, clock, record=records.append)
    vehicles = ModeVehicles(usm, **kw)
    usm.attach_vehicles(vehicles)
    if status is not None:
        usm.on_status(status)
    return usm, vehicles, records


def _audit(records: list[object]) -> list[AuditEntry]:
    return [r for r in records if isinstance(r, AuditEntry) and r.action.startswith("operator_")]


@pytest.mark.parametrize(
    ("status", "uas", "command", "operator", "source", "reason"),
    [
        (FLYING, "UAS9", "hold", "alice", "dashboard", "unknown UAS 'UAS9'"),
        (
            FLYING,
            "UAS1",
            "brake",
            "alice",
            "dashboard",
            "unknown command 'brake'; expected one of hold, land, rtl, resume",
        ),
        (FLYING, "UAS1", "hold", "bob", "mqtt", "operator 'bob' does not fly UAS1"),
        (None, "UAS1", "hold", "alice", "dashboard", "no link: nothing heard from sysid 1"),
        (
            replace(FLYING, autopilot=Autopilot.UNKNOWN),
            "UAS1",
            "rtl",
            "alice",
            "dashboard",
            "sysid 1: unknown autopilot, its modes are not known",
        ),
        (replace(FLYING, armed=False), "UAS1", "land", "x", "console", "sysid 1 is disarmed"),
        (replace(FLYING, landed=True), "UAS1", "hold", "x", "console", "sysid 1 is on the ground"),
        (
            replace(FLYING, mission_total=0),
            "UAS1",
            "resume",
            "alice",
            "mqtt",
            "sysid 1 has no mission to resume",
        ),
    ],
)
async def test_refused_with_the_reason_audited_and_nothing_sent(
    status: VehicleStatus | None, uas: str, command: str, operator: str, source: str, reason: str
) -> None:
    usm, vehicles, records = _usm(status)
    result = await usm.operator_command(uas, command, operator=operator, source=source)
    assert (result.outcome.value, result.reason) == ("refused", reason)
    assert vehicles.commands == []
    [entry] = _audit(records)
    assert entry.actor == f"operator:{operator}" and entry.action == f"operator_{command}"
    assert entry.detail["outcome"] == "refused" and entry.detail["reason"] == reason
    assert any(reason in e.text for e in usm.events if e.kind == "operator")


async def test_no_vehicle_port_and_a_silent_link_are_refused() -> None:
    usm, _, _ = _usm()
    usm.on_link_health(
        LinkHealth(
            sys_id=SysId(1),
            link="udp",
            last_heard_t_s=T0 - 9.0,
            rate_hz=0.0,
            received=10,
            lost=0,
            bad_frames=0,
            reboots=0,
        )
    )
    result = await usm.operator_command("UAS1", "hold", operator="a", source="dashboard")
    assert result.reason == "no link: sysid 1 last heard 9 s ago"
    unlinked = Usm(usm.airspace, usm.clock)
    result = await unlinked.operator_command("UAS1", "hold", operator="a", source="dashboard")
    assert result.reason == "no vehicle link for UAS1"


@pytest.mark.parametrize("command", ["hold", "land", "rtl", "resume"])
async def test_sent_through_execute_command_and_confirmed_by_the_mode(command: str) -> None:
    usm, vehicles, records = _usm()
    result = await usm.operator_command("sys1", command, operator="alice", source="mqtt")
    assert result.outcome.value == "confirmed" and result.uas == OP
    assert [c.kind.value for c in vehicles.commands] == [command]
    sent = [r for r in records if isinstance(r, AuditEntry) and r.action == f"command_{command}"]
    assert sent[0].detail == {"ok": True, "error": "", "reason": "operator alice (mqtt)"}


async def test_a_mode_not_shown_is_only_acknowledged_and_a_nack_failed() -> None:
    usm, _, _ = _usm(follow=False)
    t0 = usm.clock.now_s()
    result = await usm.operator_command("UAS1", "hold", operator="a", source="dashboard")
    assert result.outcome.value == "acknowledged"
    assert result.reason == "vehicle still reports mission after 5 s"
    assert usm.clock.now_s() - t0 == pytest.approx(5.0, abs=0.2)
    usm, _, _ = _usm(command_ok=False)
    result = await usm.operator_command("UAS1", "rtl", operator="a", source="dashboard")
    assert result.outcome.value == "failed" and not result.ok


async def test_a_plane_in_auto_is_not_confirmed_landing_by_its_unchanged_mode() -> None:
    plane = replace(FLYING, vehicle_kind=VehicleKind.FIXED_WING, autopilot=Autopilot.ARDUPILOT)
    usm, _, _ = _usm(plane, follow=False)
    result = await usm.operator_command("UAS1", "land", operator="a", source="dashboard")
    assert result.outcome.value == "acknowledged"  # still AUTO, as before: not a proof


async def test_a_repeated_request_id_is_not_sent_twice() -> None:
    usm, vehicles, _ = _usm()
    first = await usm.operator_command(
        "UAS1", "hold", operator="alice", source="mqtt", request_id="x"
    )
    again = await usm.operator_command(
        "UAS1", "hold", operator="alice", source="mqtt", request_id="x"
    )
    assert again == first and len(vehicles.commands) == 1
    other = await usm.operator_command(
        "UAS1", "hold", operator="admin", source="mqtt", request_id="x"
    )
    assert other.ok and len(vehicles.commands) == 2  # ids are per operator


def test_parse_command_line() -> None:
    assert parse_command_line("hold UAS1") == ("hold", "UAS1")
    assert parse_command_line("RETURN uas-2") == ("rtl", "uas-2")
    assert parse_command_line("Resume X") == ("resume", "X")
    assert parse_command_line("a") is None
    assert parse_command_line("hold") is None
    assert parse_command_line("fly UAS1") is None
