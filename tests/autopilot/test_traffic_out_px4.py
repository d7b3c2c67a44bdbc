"""A real PX4 v1.15 SITL with traffic avoidance takes the traffic gcs-utm sends it.

``[traffic_out]`` on; PX4 (SIH quad) with its default ``NAV_TRAFF_AVOID 1`` (warn). An
ADS-B intruder is fed to the USM directly (not over MAVLink), 300 m north of the vehicle and
flying south at it; gcs-utm sends it to the vehicle as ADSB_VEHICLE; PX4 takes it as a
transponder report and forwards it in its own ADSB_VEHICLE stream, the only way that address
can come from the vehicle. (PX4 acts on traffic, "Traffic alert", only while flying a mission;
this vehicle stays on the ground.)
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
from tests.autopilot.autopilots import SitlProcess

pytestmark = [pytest.mark.slow, pytest.mark.network]

SPEED = 5.0
ICAO = 0xABC123
HOME = (47.397742, 8.545594)
GROUND_M = 32.34  # SIH_LOC_H0 default


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


@pytest.mark.timeout(240)
async def test_px4_reports_the_traffic_gcs_utm_sent_it(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:14550",)),
        traffic_out=TrafficOutConfig(enabled=True, radius_m=3000.0),
    )
    lat, lon = HOME
    ground_m = GROUND_M
    stop = asyncio.Event()
    seen: dict[str, Any] = {}
    relayed = Relayed()

    async def intruder(rt: Runtime) -> None:
        while True:  # an ADS-B receiver's report, 300 m north of home heading south, at 1 Hz
            t = rt.clock.now_s()
            rt.usm.on_measurement(
                Measurement(
                    source=MeasurementSource.ADSB,
                    capture_t_s=t,
                    receipt_t_s=t,
                    lat_deg=lat + 300.0 / 111_320.0,
                    lon_deg=lon,
                    alt_amsl_m=ground_m + 20.0,
                    vel_ned_mps=(-10.0, 0.0, 0.0),
                    icao24=Icao24(f"{ICAO:06x}"),
                    callsign="TEST1",
                )
            )
            await asyncio.sleep(1.0)

    async def scenario(rt: Runtime) -> None:
        rt.hub.raw_tap = relayed.tap
        feed = asyncio.create_task(intruder(rt))
        try:
            px4(instance=0, airframe="quad", home=HOME, speed=SPEED)
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
    # the track, propagated to the time it was sent (the intruder moves at 10 m/s)
    assert abs(echo.lat - round((lat + 300.0 / 111_320.0) * 1e7)) < 5000  # ~55 m
    assert seen["out"]["sent"] > 0 and seen["out"]["send_errors"] == 0
    # the vehicle's own track (sysid:1) was never sent to it, so nothing else came back
    assert {m.ICAO_address for m in seen["frames"]} == {ICAO}
    assert seen["relay"]["measurements"] > 0  # the echo fused with the intruder's track
    assert f"icao:{ICAO:06x}" in seen["tracks"]
