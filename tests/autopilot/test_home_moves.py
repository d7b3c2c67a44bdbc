"""Issue 31 on real ArduCopter: a home that moves on the ground is filed again, not only at
arming (at arming: test_px4_arming.py).

A disarmed copter's mission (altitudes above home) is filed as an operation by ``gcs-utm
serve`` (in this process, nobody answering). The pilot then moves its home with
MAV_CMD_DO_SET_HOME, as a ground station does when the take-off point is not where the
vehicle first had its fix: ArduCopter reports the new HOME_POSITION, and the operation is
filed again with that home, its waypoints as high above the new home as the mission says,
the copter still disarmed.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path

import pytest

from gcs_utm.app import Runtime
from gcs_utm.geo import haversine_m
from gcs_utm.model import Operation, SysId
from gcs_utm.store import Store
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import serve_while, until
from tests.autopilot.pilot import PilotLink, mission_items, offset_deg
from tests.autopilot.test_threats_close import _settings

SPEED = 5.0
MISSION_AGL_M = 30.0
MOVE_NORTH_M, MOVE_UP_M = 40.0, 6.0  # past the re-filing tolerances (2 m, 1 m)
DO_SET_HOME = 179
ACCEPTED = 0


@pytest.mark.timeout(180)
async def test_a_home_moved_on_the_ground_is_filed_again(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    db = tmp_path / "utm.sqlite"
    lat, lon = ARDUPILOT_DEFAULT_HOME[:2]

    def op(rt: Runtime) -> Operation | None:
        return rt.airspace.by_sys_id(SysId(1))

    async def scenario(rt: Runtime) -> tuple[Operation, Operation, bool]:
        """The operation as filed, as filed again after DO_SET_HOME, and whether it armed."""
        ardupilot(instance=0, vehicle="copter", speed=SPEED)
        heard = rt.usm.health_by_sys_id
        await until(lambda: SysId(1) in heard(), 60.0, "ArduCopter not heard")
        pilot = await asyncio.to_thread(PilotLink, 0, "ardupilot", 5762)
        try:
            await asyncio.to_thread(pilot.wait_ready)
            assert pilot.home is not None
            wps = [(*offset_deg(lat, lon, 0.0, 100.0), MISSION_AGL_M)]
            items = mission_items(1, (lat, lon), wps, autopilot="ardupilot")
            await asyncio.to_thread(pilot.upload, items)
            await until(lambda: op(rt) is not None, 40.0, "no operation from the mission")
            filed = op(rt)
            assert filed is not None and filed.home is not None
            new_lat, new_lon = offset_deg(lat, lon, 0.0, MOVE_NORTH_M)
            new_alt = filed.home.alt_amsl_m + MOVE_UP_M
            result = await asyncio.to_thread(
                pilot.command, DO_SET_HOME, 0, 0, 0, 0, new_lat, new_lon, new_alt
            )
            assert result == ACCEPTED, f"DO_SET_HOME refused: {result}"

            def moved() -> bool:
                o = op(rt)
                return (
                    o is not None
                    and o.home is not None
                    and haversine_m(o.home.lat_deg, o.home.lon_deg, new_lat, new_lon) < 1.0
                )

            await until(moved, 30.0, "the operation kept its old home")
            refiled = op(rt)
            assert refiled is not None
            armed = any(
                m.base_mode & 128
                for m in await asyncio.to_thread(pilot.poll, 1.0)
                if m.get_type() == "HEARTBEAT"
            )
            return filed, refiled, armed
        finally:
            pilot.close()

    filed, moved, armed = await serve_while(_settings(("tcp:127.0.0.1:5760",)), db, scenario, SPEED)
    assert not armed, "the copter armed: the home was not moved on the ground"
    assert moved.home is not None and filed.home is not None
    assert moved.home.alt_amsl_m == pytest.approx(filed.home.alt_amsl_m + MOVE_UP_M, abs=0.5)
    # a new plan version filed with it: the mission's altitudes are above the new home
    assert moved.plan.version > filed.plan.version
    assert "home moved" in moved.plan.reason, moved.plan.reason
    assert moved.plan.waypoints[-1].alt_amsl_m == pytest.approx(
        moved.home.alt_amsl_m + MISSION_AGL_M, abs=0.05
    )
    with Store(db) as s:  # and in the store
        stored = {o.id: o for o in s.load_operations()}[moved.id]
    assert stored.home == moved.home, (stored.home, moved.home)
