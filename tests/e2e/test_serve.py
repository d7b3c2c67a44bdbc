"""``serve`` resumes from its store: what one run filed (operations, geofences created while
running) is the airspace of the next run."""

from __future__ import annotations

import asyncio
import dataclasses
from pathlib import Path

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.model import (
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Operation,
    OperationId,
    SysId,
    VehicleKind,
    Waypoint4D,
)
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
