"""A real ArduCopter 4.6 SITL relays its simulated ADS-B traffic as ADSB_VEHICLE, and the
service tracks the aircraft as intruders named by their ICAO addresses.

ArduPilot's SITL simulates an ADS-B receiver as a serial device (``--serial5=sim:adsb``,
libraries/SITL/SIM_ADSB.cpp): ``SIM_ADSB_COUNT`` aircraft within ``SIM_ADSB_RADIUS`` of home
at ``SIM_ADSB_ALT``, reported once a second as ADSB_VEHICLE (all validity flags set, ``tslc``
1 s) to the autopilot's MAVLink ADS-B backend (``ADSB_TYPE 1`` on a ``SERIAL5_PROTOCOL 2``
port, both read at boot, hence a defaults file). The autopilot forwards what its backend
keeps (within ``ADSB_LIST_RADIUS``, 2 km on Copter) to the GCS in its ADSB stream, from its
own sysid. An aircraft that leaves the radius is re-created with a new address, so the set
of addresses grows over a run.

One scenario: ``serve --record`` on the SITL's TCP port; the relayed aircraft become
non-cooperative ``icao:<hex>`` tracks whose addresses are exactly those of the ADSB_VEHICLE
frames on the wire (read back from the recording), and a replay of the recording tracks the
same aircraft."""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from adapters.mavlink import MavlinkConfig
from gcs_utm.app import Runtime
from gcs_utm.cli.replay import replay_paths
from gcs_utm.settings import Settings
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import serve_while, until
from tests.tlog_messages import tlog_messages

pytestmark = [pytest.mark.slow, pytest.mark.network]

SPEED = 5.0
RADIUS_M = 1500.0
ADSB_PARAMS = f"""SERIAL5_PROTOCOL 2
ADSB_TYPE 1
SIM_ADSB_COUNT 3
SIM_ADSB_RADIUS {RADIUS_M:g}
SIM_ADSB_ALT 300
"""


def _intruders(rt: Runtime) -> dict[str, Any]:
    return {str(k): t for k, t in rt.tracks().items() if str(k).startswith("icao:")}


# A single ArduPilot for about 5 s: runs beside the rest of the suite (load_tolerant,
# docs/testing.md).
@pytest.mark.load_tolerant
@pytest.mark.timeout(180)
async def test_ardupilot_relays_simulated_traffic_as_intruder_tracks(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    parm = tmp_path / "adsb.parm"
    parm.write_text(ADSB_PARAMS)
    rec_dir = tmp_path / "rec"
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(
            links=("tcp:127.0.0.1:5760",), reconnect_min_s=0.2, reconnect_max_s=1.0
        ),
    )

    async def scenario(rt: Runtime) -> tuple[dict[str, Any], dict[str, Any]]:
        """The intruder tracks and the relay's counters once two aircraft are tracked."""
        ardupilot(
            instance=0,
            vehicle="copter",
            speed=SPEED,
            defaults=(parm,),
            extra_args=("--serial5=sim:adsb",),
        )
        await until(lambda: len(_intruders(rt)) >= 2, 90.0, "no relayed aircraft tracked")
        await asyncio.sleep(2.0)
        return _intruders(rt), dataclasses.asdict(rt.hub.adsb_relay.counters)

    db = tmp_path / "utm.sqlite"
    intruders, relay = await serve_while(settings, db, scenario, SPEED, record_dir=rec_dir)
    assert relay["measurements"] >= 2 and relay["invalid"] == 0, relay
    # the addresses on the wire, from the recording of the link
    (tlog,) = rec_dir.glob("*.tlog")
    frames = [m for _, m in tlog_messages(tlog) if m.get_type() == "ADSB_VEHICLE"]
    on_wire = {f"icao:{m.ICAO_address:06x}" for m in frames}
    assert frames and all(m.get_srcSystem() == 1 for m in frames)  # relayed by the autopilot
    assert all(m.callsign.startswith("SIM") for m in frames)  # SIM_ADSB's callsigns
    assert set(intruders) <= on_wire and len(intruders) >= 2
    lat0, lon0, _, _ = ARDUPILOT_DEFAULT_HOME
    for tid, t in intruders.items():
        assert not t.cooperative and t.icao24 == tid.removeprefix("icao:")
        # within the simulated radius of home (plus a second of flight at <= 60 m/s)
        d_north_m = (t.lat_deg - lat0) * 111_320.0
        d_east_m = (t.lon_deg - lon0) * 111_320.0 * 0.758  # cos(40.66 deg)
        assert (d_north_m**2 + d_east_m**2) ** 0.5 < RADIUS_M + 200.0, (tid, t)
        # SIM_ADSB reports SIM_ADSB_ALT (+/- its random climb) as the altitude, not AMSL
        assert 0.0 < t.alt_amsl_m < 1000.0, (tid, t)
    # the replay of the recording tracks every aircraft seen live
    report = await replay_paths([rec_dir])
    assert set(intruders) <= set(report["tracks"]), sorted(report["tracks"])
    assert report["counters"]["adsb_relay"]["measurements"] >= relay["measurements"]
