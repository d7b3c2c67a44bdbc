"""Error storms a sender can trigger are bounded (issue 32 item 3): a failing mission
download backs off (capped before it overflows; arming and mission changes wait for it), the
failure counter per vehicle is bounded, and a task that fails again and again is logged once
per interval with a count, never a traceback per frame."""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import os
import sys
import time
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import Autopilot, SysId
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm
from gcs_utm.services.vehicle_ops import _FAILURES_CAP, _RETRY_MAX_S
from gcs_utm.settings import Settings

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import FakeVehicles


class _Key:
    sys_id = 7


class _Info:
    key = _Key()
    autopilot = Autopilot.PX4
    vehicle_kind = None


class _Refusing(FakeVehicles):
    """A vehicle that never answers a mission download."""

    def __init__(self) -> None:
        super().__init__()
        self.downloads = 0

    async def download_mission(self, sys_id: SysId) -> list[object]:
        self.downloads += 1
        raise TimeoutError("no MISSION_COUNT")


def _status(t_s: float, armed: bool) -> VehicleStatus:
    return VehicleStatus(
        sys_id=SysId(7), t_s=t_s, autopilot=Autopilot.PX4, mode=FlightMode.HOLD, armed=armed
    )


async def test_arming_toggles_wait_for_the_backoff_and_the_counter_is_bounded() -> None:
    """Downloads started by arming used to skip the back-off: every toggle failed one more
    download, and past ~1,024 failures 2.0 ** n raised OverflowError in the task."""
    clock = ManualClock(1000.0)
    usm = Usm(Airspace(), clock)
    port = _Refusing()
    usm.attach_vehicles(port)
    usm.on_vehicle(_Info())
    await usm.drain()
    for k in range(2000):  # 200 s of a sender toggling armed every 0.1 s
        clock.advance(0.1)
        usm.on_status(_status(clock.now_s(), armed=k % 2 == 0))
        await usm.drain()
    # 2, 4, 8, 16 s, then every 30 s: a handful of downloads, not one per arming
    assert port.downloads <= 12
    v = usm.vehicle_ops._vehicles[SysId(7)]
    # the counter and the back-off survive any number of failures
    for _ in range(5000):
        usm.vehicle_ops._download_failed(v, TimeoutError("x"))
    assert v.failures == _FAILURES_CAP
    assert v.retry_at_s == pytest.approx(clock.now_s() + _RETRY_MAX_S)


async def test_a_task_failing_on_every_frame_is_logged_once_per_interval(
    caplog: pytest.LogCaptureFixture,
) -> None:
    usm = Usm(Airspace(), ManualClock(0.0))

    async def broken() -> None:
        raise OverflowError("(34, 'Numerical result out of range')")

    with caplog.at_level(logging.INFO, logger="gcs_utm.services.usm"):
        for _ in range(500):
            usm._spawn(broken())
        await usm.drain()
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and errors[0].exc_info is not None
    assert "OverflowError" in errors[0].getMessage()
    assert usm._task_errors.held_total == 499


async def test_a_sender_toggling_armed_with_time_going_back_cannot_flood_the_log(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The campaign's storm over loopback UDP against ``serve``: one unkeyed sysid toggling
    armed while its time_boot_ms jumps back (each jump a reboot, which ends the download in
    flight). Before: a failed download per toggle, one log line each (~80 a second, and
    OverflowError tracebacks past ~1,024)."""
    settings = dataclasses.replace(Settings(), mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)))
    stop = asyncio.Event()
    seen: dict[str, object] = {}

    async def storm(rt: Runtime) -> None:
        loop = asyncio.get_running_loop()
        port = rt.hub.local_port(rt.hub.link_names()[0])
        transport, _ = await loop.create_datagram_endpoint(
            asyncio.DatagramProtocol, local_addr=("127.0.0.1", 0)
        )
        enc = mav.MAVLink(None, srcSystem=7, srcComponent=1)
        end = time.monotonic() + 3.0
        i = 0
        try:
            while time.monotonic() < end:
                for _ in range(20):
                    i += 1
                    armed = 128 if i % 2 else 0
                    hb = enc.heartbeat_encode(2, 12, 1 | armed, 4 << 16 | 4 << 24, 4)
                    gp = enc.global_position_int_encode(
                        100_000 - (i % 50) * 1000, 473977418, 85455939, 500000, 20000, 0, 0, 0, 0
                    )
                    for m in (hb, gp):
                        transport.sendto(bytes(m.pack(enc)), ("127.0.0.1", port))
                await asyncio.sleep(0.005)
            seen["frames"] = i
            seen["downloads"] = rt.usm.vehicle_ops.counters["downloads"]
        finally:
            transport.close()
            stop.set()

    drivers: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        drivers.append(asyncio.create_task(storm(rt)))

    with caplog.at_level(logging.INFO):
        code = await serve(
            settings,
            db_path=tmp_path / "utm.sqlite",
            operator=OperatorMode.NONE,
            headless=False,
            stop=stop,
            on_runtime=on_runtime,
        )
    await drivers[0]
    assert code == 0
    assert isinstance(seen["frames"], int) and seen["frames"] > 1000
    assert isinstance(seen["downloads"], int) and seen["downloads"] <= 4
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(caplog.records) < 40, [r.getMessage() for r in caplog.records][:50]
