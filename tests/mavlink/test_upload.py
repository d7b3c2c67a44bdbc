"""Mission upload/download and commands against the scripted vehicle (conftest.FakeVehicle)."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from adapters.mavlink import MavlinkError, UploadFailure, plan_to_mission_items
from gcs_utm.messages import FlightMode
from gcs_utm.model import (
    Command,
    CommandKind,
    FlightPlan,
    OperationId,
    Position,
    SysId,
    Waypoint4D,
)


def _plan(n: int = 10) -> FlightPlan:
    wps = tuple(
        Waypoint4D(lat_deg=47.3977 + 0.0005 * i, lon_deg=8.5456, alt_amsl_m=500.0 + i, t_s=10.0 * i)
        for i in range(n)
    )
    return FlightPlan(operation_id=OperationId("op1"), version=2, waypoints=wps)


async def test_upload_verified_sets_current_and_mission_mode(env: Any) -> None:
    v = await env.vehicle(1)
    res = await env.hub.upload_plan(SysId(1), _plan(), start_index=3)
    assert res.ok and res.verified, res
    assert res.items == 19 and res.current_set and res.mode_set
    items = plan_to_mission_items(_plan(), start_index=3)
    assert [m.command for m in v.mission] == [i.command for i in items]
    assert [m.x for m in v.mission] == [i.x for i in items]
    assert v.current == 5  # DO_CHANGE_SPEED before waypoint 3
    modes = [(c.param2, c.param3) for c in v.commands if c.command == 176]
    assert modes == [(4.0, 4.0)]  # PX4 AUTO.MISSION
    got = await env.hub.download_mission(SysId(1))
    assert len(got) == 19 and got[6].z == 503.0
    v.close()


async def test_upload_to_a_disarmed_vehicle_sets_no_mission_mode(env: Any) -> None:
    """After an upload, AUTO was set on disarmed vehicles, overriding the pilot's mode
    (issue 31.2): on the ground the upload is verified and made current, the mode left."""
    v = await env.vehicle(1)
    v.armed = False
    v.heartbeat()
    await asyncio.sleep(0.05)
    res = await env.hub.upload_plan(SysId(1), _plan(), start_index=3)
    assert res.ok and res.verified and res.current_set, res
    assert not res.mode_set
    assert [c for c in v.commands if c.command == 176] == []  # no DO_SET_MODE
    v.close()


async def test_upload_answers_old_mission_request(env: Any) -> None:
    v = await env.vehicle(2)
    v.faults.old_request = True
    res = await env.hub.upload_plan(SysId(2), _plan(4))
    assert res.verified, res
    v.close()


async def test_upload_with_loss_retries_and_verifies(env: Any) -> None:
    v = await env.vehicle(3, rerequest_s=0.05, seed=7)
    v.faults.drop = 0.2
    res = await env.hub.upload_plan(SysId(3), _plan())
    assert res.ok and res.verified, res
    assert res.attempts >= 1
    v.close()


async def test_nack_is_reported_not_verified(env: Any) -> None:
    v = await env.vehicle(4)
    v.faults.nack = 4  # MAV_MISSION_NO_SPACE
    res = await env.hub.upload_plan(SysId(4), _plan())
    assert not res.ok and not res.verified
    assert "NO_SPACE" in res.error
    assert env.hub.counters.uploads_failed == 1
    v.close()


async def test_silent_vehicle_fails_within_deadline(env: Any) -> None:
    v = await env.vehicle(5)
    v.faults.silent = True
    t0 = asyncio.get_running_loop().time()
    res = await env.hub.upload_plan(SysId(5), _plan(), deadline_t_s=env.hub.clock.now_s() + 0.6)
    assert not res.verified and "deadline" in res.error
    assert asyncio.get_running_loop().time() - t0 < 1.0
    # the vehicle was told the transfer is cancelled
    await asyncio.sleep(0.05)
    assert any(m.get_type() == "MISSION_ACK" and m.type == 15 for m in v.received)
    v.close()


async def test_readback_mismatch_is_not_verified(env: Any) -> None:
    v = await env.vehicle(6)
    v.faults.corrupt_readback = True
    res = await env.hub.upload_plan(SysId(6), _plan(3))
    assert not res.verified and "readback" in res.error
    v.close()


async def test_download_restarts_on_a_refusal_at_most_twice(env: Any) -> None:
    """A MISSION_ACK refusal during a download starts it over (MISSION_REQUEST_LIST again);
    a third refusal fails it, naming the result."""
    v = await env.vehicle(16)
    res = await env.hub.upload_plan(SysId(16), _plan(3))
    assert res.verified, res
    v.faults.refuse_readback = 2
    lists = sum(m.get_type() == "MISSION_REQUEST_LIST" for m in v.received)
    got = await env.hub.download_mission(SysId(16))
    assert len(got) == len(v.mission)
    assert sum(m.get_type() == "MISSION_REQUEST_LIST" for m in v.received) - lists == 3
    v.faults.refuse_readback = 3
    with pytest.raises(MavlinkError, match="refused the download: MAV_MISSION_ERROR"):
        await env.hub.download_mission(SysId(16))
    v.close()


async def test_reboot_mid_upload_fails(env: Any) -> None:
    v = await env.vehicle(7)
    v.position()
    v.faults.reboot_after_items = 3
    res = await env.hub.upload_plan(SysId(7), _plan())
    assert not res.verified and "reboot" in res.error
    v.close()


async def test_unknown_vehicle_is_an_error_result(env: Any) -> None:
    res = await env.hub.upload_plan(SysId(99), _plan())
    assert not res.ok and "no vehicle" in res.error


async def test_commands_px4_modes_land_reposition(env: Any) -> None:
    v = await env.vehicle(8)
    op = OperationId("op1")
    for kind, expect in [
        (CommandKind.HOLD, (4.0, 3.0)),
        (CommandKind.RESUME, (4.0, 4.0)),
        (CommandKind.RTL, (4.0, 5.0)),
    ]:
        r = await env.hub.send_command(SysId(8), Command(kind=kind, operation_id=op))
        assert r.ok and r.attempts == 1, r
        assert (v.commands[-1].param2, v.commands[-1].param3) == expect
    r = await env.hub.send_command(SysId(8), Command(kind=CommandKind.LAND, operation_id=op))
    assert r.ok and v.commands[-1].command == 21
    target = Position(lat_deg=47.4, lon_deg=8.55, alt_amsl_m=520.0)
    r = await env.hub.send_command(
        SysId(8), Command(kind=CommandKind.GOTO, operation_id=op, target=target)
    )
    last = v.commands[-1]
    assert r.ok and last.get_type() == "COMMAND_INT" and last.command == 192
    assert (last.x, last.y, last.z) == (474000000, 85500000, 520.0)
    v.close()


async def test_command_retries_increment_confirmation_and_nack(env: Any) -> None:
    v = await env.vehicle(9)
    v.faults.drop_commands = 2
    r = await env.hub.send_command(
        SysId(9), Command(kind=CommandKind.HOLD, operation_id=OperationId("o"))
    )
    assert r.ok and r.attempts == 3
    assert [c.confirmation for c in v.commands if c.command == 176] == [0, 1, 2]
    v.faults.command_result = 2  # DENIED
    r = await env.hub.send_command(
        SysId(9), Command(kind=CommandKind.RTL, operation_id=OperationId("o"))
    )
    assert not r.ok and r.result == 2 and "DENIED" in r.error
    v.close()


async def test_heartbeat_mode_becomes_status(env: Any) -> None:
    v = await env.vehicle(10)
    v.custom_mode = (4 << 16) | (4 << 24)
    v.heartbeat()
    await asyncio.sleep(0.05)
    last = [s for s in env.sink.statuses if s.sys_id == 10][-1]
    assert last.mode is FlightMode.MISSION and last.armed
    v.close()


async def test_failed_upload_is_retried_once_and_says_why(env: Any) -> None:
    v = await env.vehicle(11)
    v.faults.nack = 4  # MAV_MISSION_NO_SPACE, as ArduPilot answers just after boot
    asyncio.get_running_loop().call_later(0.3, setattr, v.faults, "nack", None)
    res = await env.hub.upload_plan(SysId(11), _plan(4))
    assert res.ok and res.verified and res.tries == 2 and res.failure is None, res
    v.faults.nack = 3  # MAV_MISSION_UNSUPPORTED every time
    res = await env.hub.upload_plan(SysId(11), _plan(4))
    assert not res.ok and res.tries == 2 and res.failure is UploadFailure.REFUSED
    assert "try 1" in res.error and "try 2" in res.error and "UNSUPPORTED" in res.error
    v.close()


async def test_mode_not_shown_in_heartbeat_fails_the_upload(env: Any) -> None:
    v = await env.vehicle(12)
    v.faults.command_result = 4  # FAILED: the vehicle stays where it is
    res = await env.hub.upload_plan(SysId(12), _plan(4))
    assert res.verified and res.current_set and not res.ok
    assert res.failure is UploadFailure.MODE_NOT_SET and "FAILED" in res.error
    v.close()
