"""Operator commands from the dashboard as a pilot uses them (Textual's ``run_test`` pilot at
80x24): select the UAS, press a command key, confirm; the command reaches a ``sitl`` vehicle
over the real MAVLink hub, the vehicle's mode changes, and the audit records it. A vehicle
that cannot do it (disarmed) gets a refusal whose reason is on the screen and in the audit."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import pytest

import sitl
from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import ScaledClock
from gcs_utm.dashboard.tui import DashboardApp
from gcs_utm.messages import FlightMode
from gcs_utm.model import AuditEntry, SysId
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm

pytestmark = [pytest.mark.network, pytest.mark.timeout(90)]

SPEED = 2.0
"""Simulated seconds per wall second. The commands refuse a vehicle not heard for 5 simulated
s (``OperatorCommands.link_timeout_s``): at 5x that was 1 s of wall time, which a loaded CI
worker stalled through once ("no link: sysid 1 last heard 5 s ago"); at 2x it takes 2.5 s."""

HOME = (47.397742, 8.545594, 488.0)
MISSION = tuple(
    sitl.MissionItemSpec(
        lat_deg=HOME[0] + 0.001 * k, lon_deg=HOME[1], alt_amsl_m=HOME[2] + 15.0, speed_mps=5.0
    )
    for k in (1, 2, 3)
)


@dataclass
class Rig:
    usm: Usm
    fleet: sitl.Fleet
    records: list[object] = field(default_factory=list)

    def audit(self, action: str) -> list[AuditEntry]:
        return [r for r in self.records if isinstance(r, AuditEntry) and r.action == action]


@asynccontextmanager
async def _rig(*, fly: bool) -> AsyncIterator[Rig]:
    """A PX4 ``sitl`` multirotor with a mission, connected to a USM through the hub; ``fly``:
    it takes off into its mission at once."""
    clock = ScaledClock(SPEED)
    sim = sitl.SimTime(SPEED, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    records: list[object] = []
    usm = Usm(Airspace(), clock, record=records.append)
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2)
    async with MavlinkHub(cfg, clock, usm) as hub:
        usm.attach_vehicles(hub)
        spec = sitl.VehicleSpec(
            instance=0,
            home_lat_deg=HOME[0],
            home_lon_deg=HOME[1],
            home_alt_amsl_m=HOME[2],
            mission=MISSION,
            auto_start_at_s=1.0 if fly else None,
            gcs_port=hub.local_port(next(iter(hub._links))),
            bind_port=0,
        )
        async with sitl.Fleet([spec], sim) as fleet:
            yield Rig(usm, fleet, records)
            await usm.drain()


async def _until(what: str, check: Callable[[], bool], timeout_s: float = 30.0) -> None:
    end = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        await asyncio.sleep(0.05)


def _flying(usm: Usm) -> bool:
    """Airborne in its mission (the mission filed as an operation)."""
    flight = [f for (sys_id, _), f in usm.flight.items() if sys_id == 1]
    return (
        "sys1" in usm.airspace.operations
        and bool(flight)
        and flight[0].airborne
        and _mode(usm) is FlightMode.MISSION
    )


def _mode(usm: Usm) -> FlightMode | None:
    s = usm.statuses_by_sys_id().get(SysId(1))
    return None if s is None else s.mode


async def test_h_then_y_holds_the_selected_uas_and_the_audit_records_it() -> None:
    async with _rig(fly=True) as rig:
        usm = rig.usm
        app = DashboardApp(usm, dict, refresh_s=0.1)
        async with app.run_test(size=(80, 24)) as pilot:
            await _until("the vehicle flying its mission", lambda: _flying(usm))
            await pilot.press("h")
            await pilot.pause()
            line = str(app.query_one("#command").render())
            assert "HOLD (brake) sys1?" in line  # asked, not sent
            assert app.commands.results == [] and rig.fleet.vehicles[0].mode != "HOLD"
            await pilot.press("y")
            await _until("the command's outcome", lambda: bool(app.commands.results))
            await pilot.pause()
            result = app.commands.results[0]
            assert result.outcome.value == "confirmed", result
            assert _mode(usm) is FlightMode.HOLD  # read back from HEARTBEAT
            assert rig.fleet.vehicles[0].mode == "HOLD"
            assert "hold sys1: confirmed" in str(app.query_one("#command").render())
            # resume: m, m (the same key twice) puts it back on its mission
            await pilot.press("m", "m")
            await _until("the resume outcome", lambda: len(app.commands.results) == 2)
            assert app.commands.results[1].outcome.value == "confirmed", app.commands.results[1]
            assert _mode(usm) is FlightMode.MISSION
    hold = rig.audit("operator_hold")
    assert len(hold) == 1 and hold[0].actor == "operator:dashboard"
    assert hold[0].subject == "sys1" and hold[0].detail["outcome"] == "confirmed"
    assert hold[0].detail["source"] == "dashboard"
    # the same verified path as EM's commands: its command audit, with the operator as reason
    sent = rig.audit("command_hold")
    assert len(sent) == 1 and sent[0].detail["ok"] is True
    assert sent[0].detail["reason"] == "operator dashboard (dashboard)"
    assert rig.audit("operator_resume")[0].detail["outcome"] == "confirmed"


async def test_escape_cancels_and_a_disarmed_vehicle_is_refused_with_the_reason() -> None:
    async with _rig(fly=False) as rig:
        usm = rig.usm
        app = DashboardApp(usm, dict, refresh_s=0.1)
        async with app.run_test(size=(80, 24)) as pilot:
            await _until(
                "the operation from the vehicle", lambda: "sys1" in usm.airspace.operations
            )
            await _until("the vehicle's status", lambda: _mode(usm) is not None)
            await pilot.press("l", "escape", "y")  # cancelled: the y confirms nothing
            await pilot.pause()
            assert app.commands.results == []
            assert "land cancelled" in str(app.query_one("#command").render())
            await pilot.press("l", "l")
            await _until("the refusal", lambda: bool(app.commands.results))
            await pilot.pause()
            screen = str(app.query_one("#command").render())
    assert app.commands.results[0].outcome.value == "refused"
    assert "land sys1: refused (sysid 1 is disarmed)" in screen
    refused = rig.audit("operator_land")
    assert len(refused) == 1 and refused[0].detail["reason"] == "sysid 1 is disarmed"
    assert rig.audit("command_land") == []  # nothing was sent


async def test_typed_commands_on_the_line_prompt_ask_then_send() -> None:
    from io import StringIO

    from rich.console import Console

    from gcs_utm.dashboard.line import LinePrompt

    async with _rig(fly=True) as rig:
        usm = rig.usm
        out = StringIO()
        prompt = LinePrompt(usm, dict, console=Console(file=out, width=100))
        await _until("the vehicle flying its mission", lambda: _flying(usm))
        for line in ("land nosuch", "y", "rtl sys1", "n", "hold sys1"):
            assert await prompt.handle(line) is None
        assert prompt.commands.results == [] or prompt.commands.results[0].uas == "nosuch"
        assert _mode(usm) is FlightMode.MISSION  # asked, not sent yet
        await prompt.handle("y")
        await _until("two outcomes", lambda: len(prompt.commands.results) == 2)
    text = out.getvalue()
    first, second = prompt.commands.results
    assert (first.outcome.value, first.reason) == ("refused", "unknown UAS 'nosuch'")
    assert "RETURN TO LAUNCH sys1? y + Enter sends it" in text and "rtl sys1 cancelled" in text
    assert second.outcome.value == "confirmed" and "hold sys1: confirmed" in text
    assert [e.detail["outcome"] for e in rig.audit("operator_hold")] == ["confirmed"]
    assert rig.audit("operator_rtl") == [] and rig.audit("command_rtl") == []
    assert rig.audit("operator_hold")[0].detail["source"] == "console"
