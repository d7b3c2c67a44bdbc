"""A real ArduCopter 4.6 SITL with ADS-B avoidance takes the traffic gcs-utm sends it.

``[traffic_out]`` on; ArduCopter with ``ADSB_TYPE 1`` (MAVLink ADS-B, which also takes
ADSB_VEHICLE from its other MAVLink links) and ``AVD_ENABLE 1`` (AP_Avoidance). An ADS-B
intruder is fed to the USM directly (not over MAVLink), 600 m from the vehicle; gcs-utm sends
it to the vehicle as ADSB_VEHICLE, and ArduPilot reports it back in its own ADS-B list (its
ADSB_VEHICLE stream to the GCS, from its own system id): the only way that address can be
on the link. The echo fuses with the intruder's track; the vehicle's own track is never sent.
"""

from __future__ import annotations

import asyncio
import dataclasses
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig
from adapters.mavlink.traffic_out import TrafficOutConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.model import Icao24, Measurement, MeasurementSource
from gcs_utm.settings import Settings
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess

pytestmark = [pytest.mark.slow, pytest.mark.network]

SPEED = 2.0
ICAO = 0xABC123
PARAMS = "ADSB_TYPE 1\nAVD_ENABLE 1\n"


class Relayed:
    """ADSB_VEHICLE frames the vehicle (sysid 1) sends, read from the hub's raw tap."""

    def __init__(self) -> None:
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.frames: list[Any] = []

    def tap(self, link: str, data: bytes, t_s: float) -> None:
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "ADSB_VEHICLE" and m.get_srcSystem() == 1:
                self.frames.append(m)


async def _until(cond: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(what)
        await asyncio.sleep(0.1)


@pytest.mark.timeout(180)
async def test_ardupilot_reports_the_traffic_gcs_utm_sent_it(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    parm = tmp_path / "traffic.parm"
    parm.write_text(PARAMS)
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(
            links=("tcp:127.0.0.1:5760",), reconnect_min_s=0.2, reconnect_max_s=1.0
        ),
        traffic_out=TrafficOutConfig(enabled=True, radius_m=3000.0),
    )
    lat, lon, ground_m, _ = ARDUPILOT_DEFAULT_HOME
    stop = asyncio.Event()
    seen: dict[str, Any] = {}
    relayed = Relayed()

    async def intruder(rt: Runtime) -> None:
        while True:  # an ADS-B receiver's report, 600 m north of home, once a second
            t = rt.clock.now_s()
            rt.usm.on_measurement(
                Measurement(
                    source=MeasurementSource.ADSB,
                    capture_t_s=t,
                    receipt_t_s=t,
                    lat_deg=lat + 600.0 / 111_320.0,
                    lon_deg=lon,
                    alt_amsl_m=ground_m + 100.0,
                    icao24=Icao24(f"{ICAO:06x}"),
                    callsign="TEST1",
                )
            )
            await asyncio.sleep(1.0)

    async def scenario(rt: Runtime) -> None:
        rt.hub.raw_tap = relayed.tap
        feed = asyncio.create_task(intruder(rt))
        try:
            ardupilot(instance=0, vehicle="copter", speed=SPEED, defaults=(parm,))
            await _until(
                lambda: any(m.ICAO_address == ICAO for m in relayed.frames),
                90.0,
                "the vehicle never reported the traffic it was sent",
            )
            seen["frames"] = list(relayed.frames)
            seen["out"] = dataclasses.asdict(rt.traffic_out.counters)
            seen["relay"] = dataclasses.asdict(rt.hub.adsb_relay.counters)
            seen["tracks"] = sorted(str(k) for k in rt.tracks())
        finally:
            feed.cancel()
            stop.set()

    async def on_runtime(rt: Runtime) -> None:
        seen["task"] = asyncio.create_task(scenario(rt))

    code = await serve(
        settings,
        db_path=tmp_path / "utm.sqlite",
        operator=OperatorMode.NONE,
        headless=False,
        stop=stop,
        on_runtime=on_runtime,
        speed=SPEED,
    )
    await seen["task"]
    assert code == 0
    echo = [m for m in seen["frames"] if m.ICAO_address == ICAO][-1]
    assert abs(echo.lat - round((lat + 600.0 / 111_320.0) * 1e7)) < 100  # ~1 m
    assert seen["out"]["sent"] > 0 and seen["out"]["send_errors"] == 0
    # the vehicle's own track (sysid:1) was never sent to it, so nothing else came back
    assert {m.ICAO_address for m in seen["frames"]} == {ICAO}
    assert seen["relay"]["measurements"] > 0  # the echo fused with the intruder's track
    assert f"icao:{ICAO:06x}" in seen["tracks"]
