"""`gcs-utm sitl`: scenario vehicles as one PX4-like fleet sending to the GCS address."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from gcs_utm.app import vehicle_specs
from gcs_utm.cli import main
from gcs_utm.cli.sitl import parse_host_port, run_sitl
from gcs_utm.scenario import load_any

UC1 = Path(__file__).resolve().parents[2] / "config/scenarios/use_case_1.toml"


def test_vehicle_specs_of_use_case_1() -> None:
    sc = load_any(UC1, t0_s=1_700_000_000.0)
    specs = vehicle_specs(sc, lead_s=10.0, gcs_host="10.0.0.5", gcs_port=14551)
    assert [s.system_id for s in specs] == [int(v.sys_id or 0) for v in sc.vehicles]
    assert sorted(s.system_id for s in specs) == [1, 2]
    for s, v in zip(specs, sc.vehicles, strict=True):
        assert (s.gcs_host, s.gcs_port, s.bind_port) == ("10.0.0.5", 14551, None)
        assert len(s.mission) == len(v.plan.waypoints)
        first = v.plan.waypoints[0]
        assert (s.mission[0].lat_deg, s.mission[0].lon_deg) == (first.lat_deg, first.lon_deg)
        assert s.kind == v.vehicle_kind.value
        # started before the filed start (+ delay) by at most the climb and the margin
        due = 10.0 + (first.t_s - sc.t0_s) + v.start_delay_s
        assert s.auto_start_at_s is not None and 0.5 <= s.auto_start_at_s <= due
    eph = vehicle_specs(sc, lead_s=10.0, ephemeral_ports=True)
    assert all(s.bind_port == 0 for s in eph)


def test_parse_host_port() -> None:
    assert parse_host_port("127.0.0.1:14550") == ("127.0.0.1", 14550)
    for bad in ("14550", "host:", "host:0", "host:x"):
        with pytest.raises(Exception, match="HOST:PORT"):
            parse_host_port(bad)


class _Gcs(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.heartbeats: dict[int, int] = {}

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "HEARTBEAT":
                sid = m.get_srcSystem()
                self.heartbeats[sid] = self.heartbeats.get(sid, 0) + 1


async def test_sitl_sends_heartbeats_of_both_vehicles_to_the_gcs() -> None:
    loop = asyncio.get_running_loop()
    transport, gcs = await loop.create_datagram_endpoint(_Gcs, local_addr=("127.0.0.1", 0))
    port = transport.get_extra_info("sockname")[1]
    stop = asyncio.Event()
    task = asyncio.create_task(
        run_sitl(
            UC1, speed=50.0, gcs=("127.0.0.1", port), lead_s=1.0, ephemeral_ports=True, stop=stop
        )
    )
    try:
        # each vehicle powers on when its operation starts (UAS2's plan starts at t0 + 70 s):
        # 2 s at speed 50 is 100 simulated seconds
        await asyncio.sleep(2.0)
    finally:
        stop.set()
        await asyncio.wait_for(task, 5.0)
        transport.close()
    assert set(gcs.heartbeats) == {1, 2}
    assert all(n >= 3 for n in gcs.heartbeats.values())  # 1 Hz simulated, >= 29 s each


def test_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nname = 1\n")
    assert main(["sitl", str(bad), "--ephemeral-ports"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gcs-utm sitl: ")
    assert main(["sitl", str(UC1), "--speed", "0"]) == 2
    with pytest.raises(SystemExit):
        main(["sitl", str(UC1), "--gcs", "nowhere"])
