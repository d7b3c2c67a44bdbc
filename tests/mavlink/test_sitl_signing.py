"""MAVLink 2 signing end to end: the hub against a ``sitl`` vehicle that enforces signing (a
key in its VehicleSpec, as PX4 MAV_SIGN_CFG). With the same key in ``[mavlink] signing_keys``
uploads verify, commands are obeyed and telemetry is accepted; without it, or with a wrong one,
the vehicle ignores uploads and commands, which end failed inside their deadline."""

from __future__ import annotations

import time

import pytest

import sitl
from adapters.mavlink import plan_to_mission_items
from gcs_utm.model import Command, CommandKind, OperationId, SysId
from tests.mavlink.test_sitl import HOME, SPEED, _assert_same, _plan, until, world

pytestmark = [pytest.mark.network, pytest.mark.timeout(60)]

KEY = "a5" * 32
WRONG = "5a" * 32
FLYING = {
    "mission": (
        sitl.MissionItemSpec(lat_deg=HOME[0] + 0.002, lon_deg=HOME[1], alt_amsl_m=HOME[2] + 30),
    ),
    "auto_start_at_s": 0.0,
    "signing_key": KEY,
}


async def test_same_key_upload_verifies_and_commands_are_obeyed() -> None:
    async with world(FLYING, signing_keys={"1": KEY}) as w:
        v = w.vehicle
        await until(lambda: len(w.sink.measurements) >= 3, 5.0, "signed telemetry not accepted")
        await until(lambda: v.mode == "MISSION" and not v.landed, 10.0, "not flying")
        plan = _plan(5)
        res = await w.hub.upload_plan(SysId(1), plan, set_mission_mode=False)
        assert res.ok and res.verified and res.current_set, res
        _assert_same(v.mission, plan_to_mission_items(plan), skip0=False)
        op = OperationId("op")
        for kind, mode in [(CommandKind.HOLD, "HOLD"), (CommandKind.LAND, "LAND")]:
            r = await w.hub.send_command(SysId(1), Command(kind=kind, operation_id=op))
            assert r.ok, (kind, r)
            assert v.mode == mode, kind
        await until(
            lambda: w.sink.statuses[-1].mode.value.upper() == "LAND", 3.0, "LAND not reported"
        )
        # nothing the hub sent was dropped, GCS heartbeats included (signed for this vehicle)
        assert v.counters["rejected_unsigned"] == 0, v.rejected_messages
        assert v.counters["rejected_bad_signature"] == 0, v.rejected_messages
        assert v.counters["uploads_ok"] == 1
        assert w.hub.counters.bad_signature == 0 and w.hub.counters.handler_errors == 0


# With a wrong key the hub drops the vehicle's frames itself (it verifies incoming
# signatures): tests/mavlink/test_links_security.py
@pytest.mark.parametrize("ground_key", [None])
async def test_without_the_key_upload_and_command_are_ignored(ground_key: str | None) -> None:
    keys = {} if ground_key is None else {"1": ground_key}
    async with world(FLYING, signing_keys=keys) as w:
        v = w.vehicle
        # without a key the vehicle's signed telemetry is read (nothing to verify it with)
        await until(lambda: len(w.sink.measurements) >= 3, 5.0, "telemetry not accepted")
        await until(lambda: v.mode == "MISSION" and not v.landed, 10.0, "not flying")
        mission_before = v.mission
        deadline = w.clock.now_s() + 2.0 * SPEED  # 2 s of wall time
        t0 = time.monotonic()
        res = await w.hub.upload_plan(SysId(1), _plan(5), deadline_t_s=deadline)
        took = time.monotonic() - t0
        assert not res.ok and not res.verified, res
        assert took < 2.0 + 0.5, took
        assert w.hub.counters.uploads_failed == 1
        assert v.mission == mission_before and v.counters["uploads_ok"] == 0
        r = await w.hub.send_command(
            SysId(1), Command(kind=CommandKind.HOLD, operation_id=OperationId("op"))
        )
        assert not r.ok and r.result is None, r
        assert v.mode == "MISSION"
        assert v.counters["commands"] == 0
        counter = "rejected_unsigned" if ground_key is None else "rejected_bad_signature"
        assert v.counters[counter] > 0
        assert v.rejected_messages.get("MISSION_COUNT", 0) >= 1, v.rejected_messages
        assert v.rejected_messages.get("COMMAND_LONG", 0) >= 1, v.rejected_messages
