"""``serve`` resumes from its store: what one run filed (operations, geofences created while
running) is the airspace of the next run."""

from __future__ import annotations

import asyncio
import dataclasses
from pathlib import Path
from typing import Any

import pytest

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.messages import PilotAnswer
from gcs_utm.model import (
    Alternative,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Maneuver,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    SysId,
    ThreatId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services.usm import AnswerOutcome
from gcs_utm.settings import Settings
from gcs_utm.store import Store

OP = OperationId("UAS1")


def _operation() -> Operation:
    plan = FlightPlan(
        operation_id=OP,
        version=1,
        waypoints=(
            Waypoint4D(lat_deg=47.3977, lon_deg=8.5456, alt_amsl_m=520.0, t_s=1e9),
            Waypoint4D(lat_deg=47.3987, lon_deg=8.5456, alt_amsl_m=520.0, t_s=1e9 + 60),
        ),
    )
    return Operation(
        id=OP,
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=plan,
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=5.0,
        operational_volume_m=20.0,
    )


async def _serve_once(db: Path, action: object) -> Runtime:
    settings = dataclasses.replace(Settings(), mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)))
    stop = asyncio.Event()
    seen: list[Runtime] = []

    async def on_runtime(rt: Runtime) -> None:
        seen.append(rt)
        if callable(action):
            await action(rt)
        asyncio.get_running_loop().call_later(0.5, stop.set)

    code = await serve(
        settings,
        db_path=db,
        operator=OperatorMode.NONE,
        headless=False,
        stop=stop,
        on_runtime=on_runtime,
    )
    assert code == 0
    return seen[0]


async def test_restart_resumes_operations_and_geofences(tmp_path: Path) -> None:
    db = tmp_path / "utm.sqlite"
    store = Store(db)
    op = _operation()
    store.save_operation(op)
    store.save_plan(op.plan)
    store.close()
    fence = Geofence(
        id=GeofenceId("fire"),
        shape=GeofenceShape.CYLINDER,
        center=LatLon(lat_deg=47.398, lon_deg=8.546),
        radius_m=80.0,
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=2000.0,
        reason="wildfire",
    )

    async def add_fence(rt: Runtime) -> None:
        assert OP in rt.airspace.operations
        await rt.usm.add_geofences([fence])

    await _serve_once(db, add_fence)
    rt = await _serve_once(db, None)
    assert rt.airspace.operation(OP).plan == op.plan
    assert [g.id for g in rt.airspace.geofences()] == ["fire"]


async def test_serve_dashboard_answers_under_the_configured_operator(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``serve`` and ``run`` attach the dashboard through one builder: an answer given on the
    dashboard of ``serve`` is audited under ``dashboard.operator``, not as "dashboard"."""
    import gcs_utm.dashboard.tui as tui

    apps: list[tui.DashboardApp] = []

    class HeadlessDashboard(tui.DashboardApp):
        async def run_async(self, **_kw: Any) -> Any:  # no terminal under pytest
            apps.append(self)
            return await super().run_async(headless=True, size=(140, 50))

    monkeypatch.setattr(tui, "DashboardApp", HeadlessDashboard)
    db = tmp_path / "utm.sqlite"
    store = Store(db)
    op = _operation()
    store.save_operation(op)
    store.save_plan(op.plan)
    store.close()
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        dashboard=dataclasses.replace(Settings().dashboard, operator="alice"),
    )
    stop = asyncio.Event()
    answers: list[PilotAnswer] = []
    driver: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        original = rt.usm.answer

        async def spy(a: PilotAnswer) -> AnswerOutcome:
            answers.append(a)
            return await original(a)

        rt.usm.answer = spy  # type: ignore[method-assign]

        async def drive() -> None:
            try:
                async with asyncio.timeout(20.0):
                    while not apps or not apps[0].is_running:
                        await asyncio.sleep(0.05)
                    await rt.usm.on_recommendation(_recommendation(rt.clock.now_s()))
                    # the dashboard ignores keys for a second after a prompt appears
                    await asyncio.sleep(1.6)
                    await apps[0].action_accept()
            finally:
                stop.set()

        driver.append(asyncio.create_task(drive()))

    code = await serve(
        settings,
        db_path=db,
        operator=OperatorMode.DASHBOARD,
        headless=False,
        stop=stop,
        on_runtime=on_runtime,
    )
    await driver[0]
    assert code == 0
    assert [(a.operator, a.source) for a in answers] == [("alice", "dashboard")]


def _recommendation(now_s: float) -> Recommendation:
    plan = _operation().plan
    return Recommendation(
        id=RecommendationId("r1"),
        version=1,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=now_s,
        deadline_t_s=now_s + 30.0,
        selected=Alternative(
            operation_id=OP, maneuver=Maneuver.GO_LEFT, plan=plan, cost=0.2, risk=0.05
        ),
    )
