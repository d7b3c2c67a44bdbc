"""Shared run of the traffic-out tests against real autopilots: ``gcs-utm serve`` with
``[traffic_out]`` on, an ADS-B intruder fed to the USM directly (not over MAVLink) north of the
vehicle's home, and the vehicle's own ADSB_VEHICLE stream read from the hub's raw tap: the
only way that address can come from the vehicle is gcs-utm having sent it there."""

from __future__ import annotations

import asyncio
import dataclasses
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig
from adapters.mavlink.traffic_out import TrafficOutConfig
from gcs_utm.app import Runtime
from gcs_utm.model import Icao24, Measurement, MeasurementSource
from gcs_utm.settings import Settings
from tests.autopilot.closed_loop import serve_while, until

ICAO = 0xABC123


@dataclass(frozen=True, slots=True)
class Intruder:
    """The ADS-B report fed at 1 Hz: ``north_m`` north of (lat, lon), ``height_m`` above the
    ground, moving at ``vel_ned_mps``."""

    lat_deg: float
    lon_deg: float
    ground_m: float
    north_m: float
    height_m: float
    vel_ned_mps: tuple[float, float, float] | None = None

    @property
    def report_lat_deg(self) -> float:
        return self.lat_deg + self.north_m / 111_320.0


@dataclass(slots=True)
class Echo:
    """What came back: the vehicle's ADSB_VEHICLE frames and serve's counters and tracks."""

    frames: list[Any]
    out: dict[str, Any]
    relay: dict[str, Any]
    tracks: list[str]


class _Relayed:
    """ADSB_VEHICLE frames the vehicle (sysid 1) sends, read from the hub's raw tap."""

    def __init__(self) -> None:
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.frames: list[Any] = []

    def tap(self, link: str, data: bytes, t_s: float) -> None:
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "ADSB_VEHICLE" and m.get_srcSystem() == 1:
                self.frames.append(m)


async def run_echo(
    mavlink: MavlinkConfig,
    start_vehicle: Callable[[], object],
    intruder: Intruder,
    *,
    speed: float,
    tmp_path: Path,
) -> Echo:
    """Run serve, start the vehicle, feed the intruder until the vehicle reports it back."""
    settings = dataclasses.replace(
        Settings(),
        mavlink=mavlink,
        traffic_out=TrafficOutConfig(enabled=True, radius_m=3000.0),
    )
    relayed = _Relayed()

    async def feed(rt: Runtime) -> None:
        while True:  # an ADS-B receiver's report, once a second
            t = rt.clock.now_s()
            rt.usm.on_measurement(
                Measurement(
                    source=MeasurementSource.ADSB,
                    capture_t_s=t,
                    receipt_t_s=t,
                    lat_deg=intruder.report_lat_deg,
                    lon_deg=intruder.lon_deg,
                    alt_amsl_m=intruder.ground_m + intruder.height_m,
                    vel_ned_mps=intruder.vel_ned_mps,
                    icao24=Icao24(f"{ICAO:06x}"),
                    callsign="TEST1",
                )
            )
            await asyncio.sleep(1.0)

    async def scenario(rt: Runtime) -> Echo:
        rt.hub.raw_tap = relayed.tap
        feeding = asyncio.create_task(feed(rt))
        try:
            start_vehicle()
            await until(
                lambda: any(m.ICAO_address == ICAO for m in relayed.frames),
                90.0,
                "the vehicle never reported the traffic it was sent",
            )
            return Echo(
                frames=list(relayed.frames),
                out=dataclasses.asdict(rt.traffic_out.counters),
                relay=dataclasses.asdict(rt.hub.adsb_relay.counters),
                tracks=sorted(str(k) for k in rt.tracks()),
            )
        finally:
            feeding.cancel()

    # serve_while: serve exited with 0
    return await serve_while(settings, tmp_path / "utm.sqlite", scenario, speed)


def assert_echo_only_of_the_intruder(echo: Echo) -> Any:
    """Serve sent traffic, never the vehicle's own track, and fused the echo with the
    intruder's track (run_echo: it ran cleanly); the last echo frame is returned for the
    caller's position check."""
    assert echo.out["sent"] > 0 and echo.out["send_errors"] == 0
    # the vehicle's own track (sysid:1) was never sent to it, so nothing else came back
    assert {m.ICAO_address for m in echo.frames} == {ICAO}
    assert echo.relay["measurements"] > 0  # the echo fused with the intruder's track
    assert f"icao:{ICAO:06x}" in echo.tracks
    return [m for m in echo.frames if m.ICAO_address == ICAO][-1]
