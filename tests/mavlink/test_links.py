"""Link kinds and identity not covered elsewhere: udpout (we call the vehicle), a sysid that
moves to a new address after silence. (TCP: ArduPilot sitl test in test_sitl.py.)"""

from __future__ import annotations

import asyncio
from typing import Any

from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import RealClock
from gcs_utm.model import Command, CommandKind, OperationId, SysId
from tests.mavlink.conftest import FakeVehicle, Sink


async def _wait(cond: Any, what: str) -> None:
    for _ in range(200):
        if cond():
            return
        await asyncio.sleep(0.01)
    raise AssertionError(what)


async def test_udpout_link_reaches_vehicle_and_talks() -> None:
    sink = Sink()
    cfg = MavlinkConfig(links=(), heartbeat_period_s=0.1, command_timeout_s=0.2)
    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        v = await FakeVehicle(0, sys_id=21).start()  # port known only after bind
        name = await hub.add_link(f"udpout:127.0.0.1:{v.port}")
        v.gcs = ("127.0.0.1", hub.local_port(name))
        # the hub speaks first: its heartbeat reaches the vehicle
        await _wait(lambda: any(m.get_type() == "HEARTBEAT" for m in v.received), "no HB")
        v.heartbeat()
        v.position()
        await _wait(lambda: bool(sink.measurements), "no measurement over udpout")
        assert sink.vehicles[0].key.link == name
        r = await hub.send_command(
            SysId(21), Command(kind=CommandKind.RTL, operation_id=OperationId("o"))
        )
        assert r.ok and v.commands[-1].param3 == 5.0
        v.close()


async def test_sysid_moving_to_new_address_after_silence() -> None:
    sink = Sink()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), address_move_s=0.2, command_timeout_s=0.2)
    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        port = hub.local_port(next(iter(hub._links)))
        a = await FakeVehicle(port, sys_id=12).start()
        a.heartbeat()
        await _wait(lambda: bool(sink.vehicles), "not discovered")
        a.close()
        await asyncio.sleep(0.3)  # silence longer than address_move_s
        b = await FakeVehicle(port, sys_id=12).start()  # same vehicle, new source port
        b.heartbeat()
        await _wait(lambda: len(sink.vehicles) == 2, "move not reported")
        assert hub.counters.address_changes == 1 and hub.counters.sysid_collisions == 0
        [info] = hub.vehicles()
        assert info.key.address == f"127.0.0.1:{b.port}"
        r = await hub.send_command(
            SysId(12), Command(kind=CommandKind.HOLD, operation_id=OperationId("o"))
        )
        assert r.ok and b.commands  # replies go to the new address
        b.close()
