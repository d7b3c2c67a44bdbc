"""Issue 31 on real PX4 (v1.15.2 SIH): a disarmed vehicle's plan is timed from its take-off,
and its home is the one PX4 takes at arming.

A mission is uploaded (verified) and the quad left on the ground for 20 simulated seconds;
the ground service (the receive stack of ``test_vehicle_time.py``, on PX4's clock) files it.
Once the pilot (on PX4's API link) arms and starts the mission, the plan is re-timed from the
take-off (a new version that starts then, not 20 s in the past) and the operation's home is
PX4's HOME_POSITION at arming, within the re-filing tolerance (PX4's home altitude wanders on
the ground).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest

from gcs_utm.clock import ScaledClock
from gcs_utm.model import SysId
from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.pilot import PilotLink
from tests.autopilot.test_vehicle_time import px4_mission, stack, until

SPEED = 8.0
GROUND_WAIT_S = 20.0  # simulated seconds on the ground between filing and arming
REQUEST_MESSAGE, HOME_POSITION = 512, 242
RETIME_WITHIN_S = 8.0  # simulated: 1 s of wall time at SPEED


@pytest.mark.timeout(180)
async def test_px4_plan_is_timed_from_take_off_with_its_home_at_arming(
    px4: Callable[..., SitlProcess],
) -> None:
    ground_m = PX4_DEFAULT_HOME[2]
    clock = ScaledClock(SPEED)
    px4(instance=0, speed=SPEED)
    async with stack("udpin:127.0.0.1:14550", clock, ground_m) as s:
        pilot = await asyncio.to_thread(PilotLink, 0)
        try:
            await asyncio.to_thread(pilot.wait_ready)
            # the mission uploaded (verified) on the service's link, as test_vehicle_time.py
            # does: the pilot's own upload competes with the service's downloads
            await until(lambda: s.usm.vehicle_ops.counters["downloads"] >= 1, 20.0, "download")
            await s.usm.drain()
            res = await s.hub.upload_items(SysId(1), px4_mission(25.0), set_mission_mode=False)
            assert res.ok and res.verified, res
            await until(s.op, 30.0, "no operation filed from the mission")
            filed = s.op()
            assert filed is not None and filed.home is not None
            t_filed = clock.now_s()
            await until(lambda: clock.now_s() > t_filed + GROUND_WAIT_S, 30.0, "clock")
            t_arm = clock.now_s()
            await asyncio.to_thread(pilot.arm_and_start)

            def retimed() -> bool:
                op = s.op()
                return (
                    op is not None
                    and op.plan.version > filed.plan.version
                    and (op.plan.start_t_s >= t_arm - 1.0)
                )

            t_started = clock.now_s()
            await until(retimed, 30.0, "the plan was not re-timed from the take-off")
            # at the start, not later when a waypoint showed the plan late (about 10 simulated
            # seconds later: the take-off climb)
            started_to_retimed_s = clock.now_s() - t_started
            await until(lambda: s.airspace.airborne(filed.id), 30.0, "not airborne")
            # PX4's home after arming, as it reports it now
            await asyncio.to_thread(pilot.command, REQUEST_MESSAGE, float(HOME_POSITION))
            await asyncio.to_thread(pilot.poll, 1.0)
            px4_home = pilot.home
        finally:
            pilot.close()
        op = s.op()
    assert op is not None and op.home is not None and px4_home is not None
    # filed on the ground from where it stood, then timed from the take-off: it starts at
    # least the ground wait later than the plan filed on the ground
    assert op.plan.start_t_s >= filed.plan.start_t_s + GROUND_WAIT_S - 1.0, (filed.plan, op.plan)
    assert started_to_retimed_s < RETIME_WITHIN_S, started_to_retimed_s
    # the home taken at arming; a HOME_POSITION PX4 sends just after it (measured 0.12 m off)
    # re-files only past [usm] home_tolerance_m (1 m)
    assert op.home.alt_amsl_m == pytest.approx(px4_home[2], abs=1.0), (op.home, px4_home)
