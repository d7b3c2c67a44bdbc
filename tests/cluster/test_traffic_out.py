"""Traffic out in a cluster (gcs_utm.cluster.selffence.OwnedTraffic) through a real hub:
behind a MAVLink router every instance hears every vehicle, and each vehicle gets its
ADSB_VEHICLE traffic only from the instance owning its operation, and from it only while
its lease deadline has not passed."""

from __future__ import annotations

import os

os.environ["MAVLINK20"] = "1"

import asyncio
from dataclasses import replace
from typing import Any

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.traffic_out import TrafficOut, TrafficOutConfig
from adapters.remoteid.config import RemoteIdConfig
from adapters.remoteid.f3411 import ODID_EPOCH_UTC_S
from gcs_utm.app import Persistence, build_runtime
from gcs_utm.clock import RealClock
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.cluster.selffence import OwnedTraffic
from gcs_utm.geo import LocalFrame
from gcs_utm.model import OperationId
from gcs_utm.services.airspace import Airspace
from gcs_utm.settings import Settings
from tests.mavlink.conftest import FakeVehicle, Sink
from tests.mavlink.test_traffic_out import TRACKS, _operation, _traffic, _until, _vehicle


async def test_only_the_owner_sends_traffic_and_only_within_its_lease() -> None:
    async with MavlinkHub(MavlinkConfig(links=("udpin:127.0.0.1:0",)), RealClock(), Sink()) as hub:
        await _check(hub)


async def _check(hub: MavlinkHub) -> None:
    v1, v2, v3 = await _vehicle(hub, 1), await _vehicle(hub, 2), await _vehicle(hub, 3)
    airspace = Airspace()
    # op-1 (vehicle 1) is this instance's, op-2 (vehicle 2) another instance's (watched in
    # the halo); vehicle 3 flies no operation here
    airspace.load([_operation("op-1", 1), _operation("op-2", 2)], ())
    policy = OwnershipPolicy()
    policy.operations_of = lambda: airspace.operations
    policy.foreign = {OperationId("op-2")}
    live = [True]
    policy.may_act = lambda: live[0]
    owned = OwnedTraffic(hub, policy, airspace.by_sys_id)
    out = TrafficOut(
        TrafficOutConfig(enabled=True, radius_m=5000.0),
        owned,
        tracks=lambda: TRACKS,
        operations=airspace.operations.values,
    )
    out.tick()
    await _until(lambda: len(_traffic(v1)) >= 2)
    sent = out.counters.sent
    assert sent == len(_traffic(v1)) and sent > 0  # vehicle 1 only
    # the lease deadline passes (a stall): nothing more to anyone
    live[0] = False
    out.tick()
    out.tick()
    assert out.counters.sent == sent
    live[0] = True
    out.tick()
    await _until(lambda: out.counters.sent == 2 * sent)
    assert _traffic(v2) == {} and _traffic(v3) == {}  # never the others' vehicles
    for v in (v1, v2, v3):
        v.close()


async def test_only_the_owner_sends_its_vehicles_the_operators_remote_id_part() -> None:
    """The operator's Remote ID part (OPEN_DRONE_ID_SYSTEM, ...) goes the same way as traffic:
    from the instance owning the vehicle's operation only, as the composition root wires it
    for a cluster member."""
    settings = replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        remote_id=RemoteIdConfig(enabled=True, operator_locations={"default": "40.0,-3.0,600"}),
    )
    policy = OwnershipPolicy()
    policy.foreign = {OperationId("op-2")}
    rt = build_runtime(
        settings, RealClock(), LocalFrame(40.0, -3.0, 600.0), _NoStore(), policy=policy
    )
    policy.operations_of = lambda: rt.airspace.operations
    rt.airspace.load([_operation("op-1", 1), _operation("op-2", 2)], ())
    async with rt.hub as hub:
        v1, v2 = await _vehicle(hub, 1), await _vehicle(hub, 2)
        for v in (v1, v2):  # both declare Remote ID (ArduPilot with DID_ENABLE=1)
            v.send(v.mav.statustext_encode(4, b"ODID: lost operator location"), lossy=False)
        await _until(lambda: {1, 2} <= set(hub.remote_id.declared))
        rt.remote_id.tick(ODID_EPOCH_UTC_S + 1000.0)
        await _until(lambda: _system(v1) != [])
        await asyncio.sleep(0.2)  # what vehicle 2 would get has arrived by now
        assert _system(v2) == []
        for v in (v1, v2):
            v.close()


def _system(v: FakeVehicle) -> list[Any]:
    return [m for m in v.received if m.get_type() == "OPEN_DRONE_ID_SYSTEM"]


class _NoStore(Persistence):
    """Nothing in this test writes to the store."""

    def __init__(self) -> None:
        pass

    @property
    def epoch(self) -> int:
        return 1
