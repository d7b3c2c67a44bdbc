"""A real ArduCopter 4.6 SITL with ADS-B avoidance takes the traffic gcs-utm sends it.

``[traffic_out]`` on; ArduCopter with ``ADSB_TYPE 1`` (MAVLink ADS-B, which also takes
ADSB_VEHICLE from its other MAVLink links) and ``AVD_ENABLE 1`` (AP_Avoidance). An ADS-B
intruder is fed to the USM directly (not over MAVLink), 600 m from the vehicle; gcs-utm sends
it to the vehicle as ADSB_VEHICLE, and ArduPilot reports it back in its own ADS-B list (its
ADSB_VEHICLE stream to the GCS, from its own system id): the only way that address can be
on the link. The echo fuses with the intruder's track; the vehicle's own track is never sent.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from adapters.mavlink import MavlinkConfig
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess
from tests.autopilot.traffic_echo import Intruder, assert_echo_only_of_the_intruder, run_echo

pytestmark = [pytest.mark.slow, pytest.mark.network]

SPEED = 2.0
PARAMS = "ADSB_TYPE 1\nAVD_ENABLE 1\n"


# A single ArduPilot for about 5 s: runs beside the rest of the suite (load_tolerant,
# docs/testing.md).
@pytest.mark.load_tolerant
@pytest.mark.timeout(180)
async def test_ardupilot_reports_the_traffic_gcs_utm_sent_it(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    parm = tmp_path / "traffic.parm"
    parm.write_text(PARAMS)
    lat, lon, ground_m, _ = ARDUPILOT_DEFAULT_HOME
    intruder = Intruder(lat, lon, ground_m, north_m=600.0, height_m=100.0)  # standing still
    echo = await run_echo(
        MavlinkConfig(links=("tcp:127.0.0.1:5760",), reconnect_min_s=0.2, reconnect_max_s=1.0),
        lambda: ardupilot(instance=0, vehicle="copter", speed=SPEED, defaults=(parm,)),
        intruder,
        speed=SPEED,
        tmp_path=tmp_path,
    )
    last = assert_echo_only_of_the_intruder(echo)
    assert abs(last.lat - round(intruder.report_lat_deg * 1e7)) < 100  # ~1 m
