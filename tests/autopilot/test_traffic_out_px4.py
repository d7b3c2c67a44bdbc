"""A real PX4 v1.15 SITL with traffic avoidance takes the traffic gcs-utm sends it.

``[traffic_out]`` on; PX4 (SIH quad) with its default ``NAV_TRAFF_AVOID 1`` (warn). An
ADS-B intruder is fed to the USM directly (not over MAVLink), 300 m north of the vehicle and
flying south at it; gcs-utm sends it to the vehicle as ADSB_VEHICLE; PX4 takes it as a
transponder report and forwards it in its own ADSB_VEHICLE stream, the only way that address
can come from the vehicle. (PX4 acts on traffic, "Traffic alert", only while flying a mission;
this vehicle stays on the ground.)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from adapters.mavlink import MavlinkConfig
from tests.autopilot.autopilots import SitlProcess
from tests.autopilot.traffic_echo import Intruder, assert_echo_only_of_the_intruder, run_echo

pytestmark = [pytest.mark.slow, pytest.mark.network]

SPEED = 5.0
HOME = (47.397742, 8.545594)
GROUND_M = 32.34  # SIH_LOC_H0 default


# One PX4 for about 10 s: runs beside the rest of the suite (load_tolerant, docs/testing.md).
@pytest.mark.load_tolerant
@pytest.mark.timeout(240)
async def test_px4_reports_the_traffic_gcs_utm_sent_it(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat, lon = HOME
    # 300 m north of home, flying south at it at 10 m/s
    intruder = Intruder(
        lat, lon, GROUND_M, north_m=300.0, height_m=20.0, vel_ned_mps=(-10.0, 0.0, 0.0)
    )
    echo = await run_echo(
        MavlinkConfig(links=("udpin:127.0.0.1:14550",)),
        lambda: px4(instance=0, airframe="quad", home=HOME, speed=SPEED),
        intruder,
        speed=SPEED,
        tmp_path=tmp_path,
    )
    last = assert_echo_only_of_the_intruder(echo)
    # the track, propagated to the time it was sent (the intruder moves at 10 m/s)
    assert abs(last.lat - round(intruder.report_lat_deg * 1e7)) < 5000  # ~55 m
