"""``gcs-utm run SCENARIO --external --fly``: external autopilots fly the scenario's plans.

For each operation of the scenario, on the vehicle with the operation's ``sys_id``:
1. wait until the vehicle is discovered and reports a position;
2. upload the operation's current plan version (the filed one, or a resolution accepted
   before the upload) through :meth:`MavlinkHub.upload_plan` (verified by readback, first
   waypoint made current; the mission mode is not set yet: the vehicle is on the ground);
3. at the first waypoint's time minus the climb time, arm (retried while the autopilot's
   pre-flight checks refuse) and take off to the first waypoint's altitude (PX4: NAV_TAKEOFF
   to an AMSL altitude; ArduCopter: GUIDED, then NAV_TAKEOFF above home; ArduPlane: armed in
   TAKEOFF mode); a fixed wing is then sent to loiter at the first waypoint;
4. at the first waypoint's time plus the scenario's ``start_delay_s`` (a late start), switch
   to mission mode and confirm it on HEARTBEAT.

A vehicle that refuses a step is left as it is: the refusal is logged as one error naming the
vehicle and the reason, recorded in the report's ``fly`` entry, and the run goes on.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field, replace
from typing import Any

from adapters.mavlink import MavlinkHub
from adapters.mavlink.transfer import CommandResult, MavlinkError
from adapters.mavlink.vehicle import VehicleState
from gcs_utm.clock import Clock
from gcs_utm.messages import FlightMode
from gcs_utm.model import (
    Autopilot,
    Command,
    CommandKind,
    FlightPlan,
    OperationId,
    SysId,
    VehicleKind,
)
from gcs_utm.scenario import Scenario
from gcs_utm.scenario.types import VehicleSetup

_log = logging.getLogger(__name__)

MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_DO_SET_MODE = 176
ARDUPLANE_TAKEOFF = 13.0  # ArduPlane's TAKEOFF custom mode
PLANE_SAFE_M = 30.0
"""Height above ground from which an ArduPlane is sent on to its first waypoint."""
DISCOVERY_GRACE_S = 60.0
"""Clock seconds after the first waypoint's time a vehicle may still be discovered."""
UPLOAD_RETRY_S = 5.0  # clock seconds between two uploads of the plan
HOME_WAIT_S = 20.0  # clock seconds to wait for HOME_POSITION after the first fix
ARM_TRY_S = 60.0  # clock seconds of arming tries (pre-flight checks refuse after boot)
ARM_RETRY_S = 2.0  # clock seconds between two arming tries
SILENT_TRIES = 3
"""Times a step is sent when the vehicle does not answer at all: each send already resends
its COMMAND_LONG (``[mavlink] command_retries``), but a loaded link or autopilot can stay
silent for longer; a refusal is final."""
TAKEOFF_CLIMB_MPS = 1.0
"""Climb rate assumed to schedule the take-off (PX4's MPC_TKO_SPEED default is 1.5 m/s)."""
TAKEOFF_MARGIN_S = 15.0  # clock seconds for arming and spool-up before the climb
TAKEOFF_TOLERANCE_M = 3.0  # below the first waypoint's altitude: the climb is done
TAKEOFF_TRIES = 3  # arm and NAV_TAKEOFF again when the vehicle disarmed or did not climb
TAKEOFF_CHECK_S = 10.0  # clock seconds after NAV_TAKEOFF by which the climb must show
TAKEOFF_MIN_CLIMB_M = 1.0  # above the ground: the vehicle has left it
MODE_CONFIRM_S = 3.0  # real seconds for HEARTBEAT to show the mission mode


class FlyRefusedError(Exception):
    """A step the vehicle refused or never did; the message says which and why."""


@dataclass(slots=True)
class FlyOutcome:
    """What ``--fly`` did to one operation's vehicle."""

    uas: str
    sys_id: int | None
    steps: list[str] = field(default_factory=list)
    uploaded: bool = False
    verified: bool = False
    armed: bool = False
    started: bool = False
    late_s: float | None = None  # mission mode set this long after the first waypoint's time
    error: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "uas": self.uas,
            "sys_id": self.sys_id,
            "uploaded": self.uploaded,
            "verified": self.verified,
            "armed": self.armed,
            "started": self.started,
            "late_s": None if self.late_s is None else round(self.late_s, 1),
            "steps": list(self.steps),
            "error": self.error,
        }


CurrentPlan = Callable[[OperationId], FlightPlan]
"""The operation's current plan version (the UTM's airspace), read at upload time."""


async def fly_scenario(
    hub: MavlinkHub,
    clock: Clock,
    scenario: Scenario,
    outcomes: list[FlyOutcome],
    *,
    current_plan: CurrentPlan | None = None,
) -> None:
    """Fly every operation of ``scenario`` on its external vehicle (one task each); fills
    ``outcomes`` as it goes, so that a run cut short still reports what was done.
    ``current_plan`` gives each operation's plan version at the time of its upload (a
    resolution accepted before the upload is not overwritten by the filed plan); without
    it the filed plan is uploaded."""
    async with asyncio.TaskGroup() as tg:
        for v in scenario.vehicles:
            out = FlyOutcome(uas=str(v.operation_id), sys_id=v.sys_id)
            outcomes.append(out)
            plan_of = current_plan or _filed_plan(v.plan)
            tg.create_task(_fly_guarded(hub, clock, v, out, plan_of), name=f"fly-{v.operation_id}")


def _filed_plan(plan: FlightPlan) -> CurrentPlan:
    def plan_of(_op_id: OperationId) -> FlightPlan:
        return plan

    return plan_of


async def _fly_guarded(
    hub: MavlinkHub, clock: Clock, v: VehicleSetup, out: FlyOutcome, plan_of: CurrentPlan
) -> None:
    try:
        if v.sys_id is None:
            raise FlyRefusedError("the operation has no sys_id: no vehicle to fly it")
        await _fly_one(hub, clock, v, out, plan_of)
    except (FlyRefusedError, MavlinkError) as exc:  # MavlinkError: the vehicle was lost
        out.error = str(exc)
        _log.error("fly %s (sys_id %s): %s", v.operation_id, v.sys_id, exc)


def _step(out: FlyOutcome, clock: Clock, text: str) -> None:
    out.steps.append(f"{clock.now_s():.1f}: {text}")
    _log.info("fly %s (sys_id %s): %s", out.uas, out.sys_id, text)


async def _fly_one(
    hub: MavlinkHub, clock: Clock, v: VehicleSetup, out: FlyOutcome, plan_of: CurrentPlan
) -> None:
    assert v.sys_id is not None
    sys_id = v.sys_id
    await _wait_fix(hub, clock, v, plan_of(v.operation_id).waypoints[0].t_s + DISCOVERY_GRACE_S)
    _step(out, clock, "discovered with a position fix")
    if not await _wait_home(hub, clock, sys_id):
        _step(out, clock, f"no HOME_POSITION within {HOME_WAIT_S:.0f} s: going on without")
    st = hub.state(v.sys_id)
    # the vehicle's own home (ArduPilot's take-off altitude is relative to it); a first
    # position can precede the autopilot's altitude origin (ArduPlane reported ~0 m AMSL)
    pos = st.home or st.last_position
    ground_m = pos.alt_amsl_m if pos is not None else v.home.alt_amsl_m
    v = await _upload(hub, clock, v, out, plan_of, ground_m=ground_m)
    first = v.plan.waypoints[0]
    takeoff_t_s = _takeoff_t_s(v.plan, ground_m)
    await clock.sleep(max(0.0, takeoff_t_s - clock.now_s()))
    await _takeoff(hub, clock, v, out, ground_m=ground_m)
    # a late start of the scenario (use case 1's start_delay_s) is flown as filed: late
    start_t_s = first.t_s + v.start_delay_s
    await clock.sleep(max(0.0, start_t_s - clock.now_s()))
    await _answered(lambda: hub.send_mode(sys_id, FlightMode.MISSION), "mission mode")
    if not await hub.wait_mode(hub.state(sys_id), FlightMode.MISSION, MODE_CONFIRM_S):
        shown = hub.state(sys_id).mode.value
        raise FlyRefusedError(f"HEARTBEAT still shows {shown}, not mission")
    out.started = True
    out.late_s = max(0.0, clock.now_s() - first.t_s)
    _step(out, clock, f"mission started ({out.late_s:.1f} s after the first waypoint's time)")


def _takeoff_t_s(plan: FlightPlan, ground_m: float) -> float:
    first = plan.waypoints[0]
    climb_m = max(0.0, first.alt_amsl_m - ground_m)
    return first.t_s - climb_m / TAKEOFF_CLIMB_MPS - TAKEOFF_MARGIN_S


async def _upload(
    hub: MavlinkHub,
    clock: Clock,
    v: VehicleSetup,
    out: FlyOutcome,
    plan_of: CurrentPlan,
    *,
    ground_m: float,
) -> VehicleSetup:
    """Upload the operation's current plan version (readback verified, first waypoint
    current), read again at each try; ``v`` with the plan uploaded. A failed upload (each is
    already tried twice) is tried again every ``UPLOAD_RETRY_S`` until the take-off time: on
    a loaded machine a transfer can overrun its budget."""
    assert v.sys_id is not None
    while True:
        plan = plan_of(v.operation_id)
        res = await hub.upload_plan(
            v.sys_id,
            plan,
            home=v.home,
            set_mission_mode=False,
            climb_rate_mps=v.max_climb_rate_mps,
        )
        out.uploaded, out.verified = res.ok, res.verified
        if res.ok:
            break
        why = f"plan upload failed ({res.failure}): {res.error}"
        if clock.now_s() + UPLOAD_RETRY_S >= _takeoff_t_s(plan, ground_m):
            raise FlyRefusedError(why)
        _step(out, clock, f"{why}; trying again")
        await clock.sleep(UPLOAD_RETRY_S)
    _step(
        out,
        clock,
        f"plan v{plan.version} uploaded and verified ({res.items} items, "
        f"current {res.current_seq})",
    )
    return replace(v, plan=plan)


async def _wait_fix(hub: MavlinkHub, clock: Clock, v: VehicleSetup, until_t_s: float) -> None:
    assert v.sys_id is not None
    while clock.now_s() < until_t_s:
        try:
            pos = hub.state(v.sys_id).last_position
        except MavlinkError:
            pos = None
        if pos is not None and not (pos.lat_deg == 0.0 and pos.lon_deg == 0.0):
            return
        await clock.sleep(0.5)
    raise FlyRefusedError("never discovered with a position fix")


async def _answered(send: Callable[[], Awaitable[CommandResult]], what: str) -> None:
    """Send a step until the vehicle answers it (at most SILENT_TRIES times); raise
    FlyRefusedError naming ``what`` if it refuses or never answers."""
    res = CommandResult(ok=False, result=None, attempts=0, error="not sent")
    for _ in range(SILENT_TRIES):
        res = await send()
        if res.ok:
            return
        if res.result is not None:  # answered: refused
            break
    raise FlyRefusedError(f"{what} refused: {res.error}")


async def _wait_home(hub: MavlinkHub, clock: Clock, sys_id: int) -> bool:
    """Until the vehicle reports its home (PX4 sets it once its position is valid; a take-off
    sent before may be accepted and never flown)."""
    end_t_s = clock.now_s() + HOME_WAIT_S
    while clock.now_s() < end_t_s:
        if hub.state(SysId(sys_id)).home is not None:
            return True
        await clock.sleep(0.5)
    return False


async def _arm(hub: MavlinkHub, clock: Clock, v: VehicleSetup, out: FlyOutcome) -> None:
    assert v.sys_id is not None
    sys_id = v.sys_id
    st = hub.state(sys_id)
    if _arduplane(st):  # armed in TAKEOFF mode, it takes off (NAV_TAKEOFF is for quadplanes)
        params = (1.0, ARDUPLANE_TAKEOFF, 0.0, 0.0, 0.0, 0.0, 0.0)
        await _answered(
            lambda: hub.command_long(sys_id, MAV_CMD_DO_SET_MODE, params), "TAKEOFF mode"
        )
    elif st.autopilot is Autopilot.ARDUPILOT:  # ArduCopter takes off in GUIDED
        await _answered(lambda: hub.send_mode(sys_id, FlightMode.GUIDED), "GUIDED")
    end_t_s = clock.now_s() + ARM_TRY_S
    error = ""
    while clock.now_s() < end_t_s:
        res = await hub.command_long(
            v.sys_id, MAV_CMD_COMPONENT_ARM_DISARM, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        )
        if res.ok:
            out.armed = True
            _step(out, clock, "armed")
            return
        error = res.error
        await clock.sleep(ARM_RETRY_S)
    raise FlyRefusedError(f"arming refused for {ARM_TRY_S:.0f} s: {error}")


async def _takeoff(
    hub: MavlinkHub,
    clock: Clock,
    v: VehicleSetup,
    out: FlyOutcome,
    *,
    ground_m: float,
) -> None:
    """NAV_TAKEOFF to the first waypoint's altitude (PX4: AMSL; ArduPilot: above home),
    then wait for the climb until the first waypoint's time (the mission mode then finishes
    any climb left). A vehicle that disarms or does not climb (an autopilot may accept the
    command and still stay on the ground right after boot) is armed and sent it again."""
    assert v.sys_id is not None
    sys_id = v.sys_id
    first = v.plan.waypoints[0]
    alt_amsl_m, first_t_s = first.alt_amsl_m, first.t_s
    st = hub.state(sys_id)
    alt = alt_amsl_m if st.autopilot is not Autopilot.ARDUPILOT else alt_amsl_m - ground_m
    takeoff = (0.0, 0.0, 0.0, math.nan, math.nan, math.nan, alt)
    why = ""
    for attempt in range(1, TAKEOFF_TRIES + 1):
        if attempt == 1 or not st.armed:
            await _arm(hub, clock, v, out)
        if not _arduplane(st):
            await _answered(
                lambda: hub.command_long(sys_id, MAV_CMD_NAV_TAKEOFF, takeoff), "take-off"
            )
        _step(out, clock, f"taking off to {alt_amsl_m:.1f} m AMSL (try {attempt})")
        # ArduPlane climbs to its own TKOFF_ALT: sent on from a safe height, it climbs the rest
        climb_to_m = min(alt_amsl_m, ground_m + PLANE_SAFE_M) if _arduplane(st) else alt_amsl_m
        why = await _climb(clock, st, climb_to_m, ground_m, first_t_s)
        if not why:
            pos = st.last_position
            _step(out, clock, f"climbed to {pos.alt_amsl_m if pos else alt_amsl_m:.1f} m AMSL")
            if st.kind is VehicleKind.FIXED_WING:
                await _wait_at_first_waypoint(hub, clock, v, out)
            return
        _step(out, clock, why)
        if why.startswith("first waypoint"):
            return
    raise FlyRefusedError(f"take-off failed {TAKEOFF_TRIES} times: {why}")


def _arduplane(st: VehicleState) -> bool:
    return st.autopilot is Autopilot.ARDUPILOT and st.kind is VehicleKind.FIXED_WING


async def _wait_at_first_waypoint(
    hub: MavlinkHub, clock: Clock, v: VehicleSetup, out: FlyOutcome
) -> None:
    """A fixed wing cannot wait above its home: after the take-off PX4 loiters where its climb
    ended, hundreds of metres out on the runway heading, and would reach the first waypoint
    late. Sent there (DO_REPOSITION, as a ground station's "go to"), it loiters around it."""
    assert v.sys_id is not None
    sys_id = v.sys_id
    goto = Command(
        kind=CommandKind.GOTO, operation_id=v.operation_id, target=v.plan.waypoints[0].position
    )
    await _answered(lambda: hub.send_command(sys_id, goto), "go-to the first waypoint")
    _step(out, clock, "sent to loiter at the first waypoint")


async def _climb(
    clock: Clock, st: VehicleState, alt_amsl_m: float, ground_m: float, first_t_s: float
) -> str:
    """Watch a take-off: "" once near ``alt_amsl_m``, else why it stopped watching."""
    check_t_s = clock.now_s() + TAKEOFF_CHECK_S
    seen_armed = False  # HEARTBEAT shows the arming a moment after its COMMAND_ACK
    while clock.now_s() < first_t_s:
        pos = st.last_position
        alt_m = pos.alt_amsl_m if pos is not None else ground_m
        if alt_m >= alt_amsl_m - TAKEOFF_TOLERANCE_M:
            return ""
        seen_armed = seen_armed or st.armed
        if seen_armed and not st.armed:
            return f"disarmed during the take-off at {alt_m:.1f} m AMSL"
        if clock.now_s() >= check_t_s and alt_m < ground_m + TAKEOFF_MIN_CLIMB_M:
            return f"no climb {TAKEOFF_CHECK_S:.0f} s after the take-off ({alt_m:.1f} m AMSL)"
        await clock.sleep(0.5)
    pos = st.last_position
    height = "unknown" if pos is None else f"{pos.alt_amsl_m:.1f} m AMSL"
    return f"first waypoint's time reached during the climb ({height})"
