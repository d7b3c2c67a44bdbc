"""Behind a MAVLink router every instance reads a vehicle's mission when it changes (the
instances share the GCS system id, so each hears the vehicle's answers to the others):
an upload by the vehicle's owner while another instance downloads the same mission still
goes through, read back and verified, and the downloads succeed. A built-in vehicle
(``gcs-utm sitl``) behind :class:`tests.cluster.router.UdpFanout`, two hubs."""

from __future__ import annotations

import asyncio
import dataclasses
import os
import socket
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"

from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import RealClock
from gcs_utm.model import SysId
from gcs_utm.scenario import load_scenario
from tests.cluster.router import UdpFanout
from tests.cluster.test_border_conflict import _free_port, _scenario, _start
from tests.mavlink.conftest import Sink


@pytest.mark.timeout(60)
async def test_an_owner_uploads_while_another_instance_downloads(tmp_path: Path) -> None:
    ports = [_free_port(socket.SOCK_DGRAM) for _ in range(2)]
    router = UdpFanout(ports)
    scenario = _scenario(tmp_path / "v.toml", "UAS1", 1, (-900.0, -300.0), 0.0, 4.0)
    gcs = f"127.0.0.1:{router.vehicle_port}"
    vehicle = _start(["sitl", "--ephemeral-ports", "--gcs", gcs, str(scenario)], tmp_path / "v.log")
    hubs: list[MavlinkHub] = []
    try:
        for port in ports:  # both with the default GCS system id, as deployed
            hub = MavlinkHub(MavlinkConfig(links=(f"udpin:127.0.0.1:{port}",)), RealClock(), Sink())
            await hub.start()
            hubs.append(hub)
        loop = asyncio.get_running_loop()
        end = loop.time() + 30.0
        while not all(h.vehicles() for h in hubs):
            assert loop.time() < end, (tmp_path / "v.log").read_text()[-2000:]
            await asyncio.sleep(0.1)
        owner, other = hubs
        before = await other.download_mission(SysId(1))
        flown = load_scenario(scenario).operations[0].plan
        plan = dataclasses.replace(
            flown,
            version=2,
            waypoints=tuple(
                dataclasses.replace(w, alt_amsl_m=w.alt_amsl_m + 10.0) for w in flown.waypoints
            ),
        )
        upload = asyncio.create_task(owner.upload_plan(SysId(1), plan))
        downloads = [await other.download_mission(SysId(1)) for _ in range(3)]
        result = await upload
        assert result.ok and result.verified, result.error
        assert all(downloads)
        after = await other.download_mission(SysId(1))  # the other reads the new mission
        mine = await owner.download_mission(SysId(1))
        assert [(i.x, i.y, i.z) for i in after] == [(i.x, i.y, i.z) for i in mine]
        assert [i.z for i in after] != [i.z for i in before]  # 10 m higher
    finally:
        for hub in hubs:
            await hub.close()
        vehicle.terminate()
        vehicle.wait(10)
        router.close()
