"""Issue 31: a mission with a DO_JUMP loop on real PX4 (v1.15.2 SIH) is filed as PX4 will fly
it, each loop repeated, not as its listed waypoints only.

The mission (uploaded after discovery, another ground station's job; here the hub's) takes off,
flies A and B, jumps back to A twice (DO_JUMP param2 = 2 repeats) and ends at C. PX4 accepts it
(verified by readback); the operation filed from it passes A and B three times each, then C,
in time order. The ground service's receive stack of ``test_vehicle_time.py`` on PX4's clock.
The upload sets PX4's current item with one MISSION_SET_CURRENT (it was ~16 in 0.45 s).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import pytest

from adapters.mavlink.mission import MissionItem
from gcs_utm.clock import ScaledClock
from gcs_utm.geo import haversine_m
from gcs_utm.model import SysId
from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.test_vehicle_time import (
    DO_CHANGE_SPEED,
    MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    MAV_FRAME_MISSION,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    stack,
    until,
)

DO_JUMP = 177
MISSION_SET_CURRENT = 41
GCS_SYS_ID = 255  # [mavlink] gcs_sys_id
SPEED = 8.0
REL_ALT_M = 25.0
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
A = (LAT0 + 0.001, LON0)
B = (LAT0 + 0.001, LON0 + 0.001)
C = (LAT0, LON0 + 0.001)


def _wp(seq: int, at: tuple[float, float], command: int = NAV_WAYPOINT) -> MissionItem:
    return MissionItem(
        seq=seq, command=command, frame=MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        x=round(at[0] * 1e7), y=round(at[1] * 1e7), z=REL_ALT_M,
    )  # fmt: skip


def _mission() -> list[MissionItem]:
    return [
        _wp(0, (LAT0, LON0), NAV_TAKEOFF),
        MissionItem(seq=1, command=DO_CHANGE_SPEED, frame=MAV_FRAME_MISSION, param1=-1.0,
                    param2=6.0),
        _wp(2, A),
        _wp(3, B),
        # back to seq 2, twice: A and B are flown three times
        MissionItem(seq=4, command=DO_JUMP, frame=MAV_FRAME_MISSION, param1=2.0, param2=2.0),
        _wp(5, C),
    ]  # fmt: skip


def _set_current(frame: bytes) -> list[int]:
    """[1] when ``frame`` is a MAVLink 2 MISSION_SET_CURRENT we sent, else [] (the tap also
    sees what PX4 sends: its system id is not ours)."""
    if len(frame) < 10 or frame[0] != 0xFD or frame[5] != GCS_SYS_ID:
        return []
    return [1] if int.from_bytes(frame[7:10], "little") == MISSION_SET_CURRENT else []


@pytest.mark.timeout(180)
async def test_px4_mission_with_a_do_jump_loop_is_filed_as_flown(
    px4: Callable[..., SitlProcess],
) -> None:
    px4(instance=0, speed=SPEED)
    async with stack("udpin:127.0.0.1:14550", ScaledClock(SPEED), GROUND_M) as s:
        await until(s.hub.vehicles, 20.0, "PX4 not discovered")
        await until(lambda: s.usm.vehicle_ops.counters["downloads"] >= 1, 10.0, "no download")
        await s.usm.drain()
        assert s.op() is None  # no mission yet
        sent: list[int] = []
        s.hub.raw_tap = lambda _link, frame, _t: sent.extend(_set_current(frame))
        res = await s.hub.upload_items(SysId(1), _mission(), set_mission_mode=False)
        s.hub.raw_tap = None
        assert res.ok and res.verified, res  # PX4 took the loop as it is
        # one MISSION_SET_CURRENT; a second only if PX4's MISSION_CURRENT took longer than
        # the command timeout (0.5 s)
        assert 1 <= len(sent) <= 2, sent
        await until(s.op, 30.0, "no operation filed from the mission with a loop")
        op = s.op()
        assert op is not None
    wps = op.plan.waypoints

    def visits(at: tuple[float, float]) -> list[int]:
        return [i for i, w in enumerate(wps) if haversine_m(w.lat_deg, w.lon_deg, *at) < 2.0]

    a, b, c = visits(A), visits(B), visits(C)
    assert (len(a), len(b), len(c)) == (3, 3, 1), op.plan
    # A, B, A, B, A, B, then C; in time order, each at the mission's altitude above home
    assert sorted(a + b + c) == [a[0], b[0], a[1], b[1], a[2], b[2], c[0]]
    assert all(x.t_s <= y.t_s for x, y in itertools.pairwise(wps)), op.plan
    assert op.home is not None
    for i in a + b + c:
        assert math.isclose(wps[i].alt_amsl_m, op.home.alt_amsl_m + REL_ALT_M, abs_tol=0.05)
