"""ADS-B in the running service: a built-in vehicle flies a plan while an SBS-1 receiver feed
(a TCP server on loopback, ephemeral port) reports an aircraft approaching it head-on at its
altitude (it follows the UAS's altitude, as a pursuing aircraft would), and a fake relay on
the vehicle's MAVLink link forwards ADSB_VEHICLE reports (pymavlink-encoded) of a distant
aircraft and of the vehicle's own transponder.

Expected: intruder tracks named by ICAO address (in the runtime and in the store), an
INTRUDER threat against the operation and EM's avoidance recommendation for it, and the
vehicle's own ADS-B fused with its track instead of becoming an intruder."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import socket
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mav

from adapters.adsb.config import AdsbConfig
from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, RunOptions, Runtime, run_scenario, serve
from gcs_utm.cli.replay import replay_file
from gcs_utm.model import ThreatKind
from gcs_utm.settings import Settings
from gcs_utm.store import Store
from tests.adsb.sbs_lines import sbs_position, sbs_velocity
from tests.adsb.test_relay import adsb_vehicle
from tests.tlog_messages import tlog_messages

pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(120)]

SPEED = 5.0
OWN_ICAO = "346617"  # UAS1's transponder
HEADON_ICAO = "a1b2c3"  # SBS-1: head-on towards UAS1 at its altitude
DISTANT_ICAO = "c0ffee"  # relayed ADSB_VEHICLE, ~3 km away
M_PER_DEG_LAT = 111_320.0
HEADON_AHEAD_M = 1500.0
HEADON_SPEED_MPS = 40.0


def m_per_deg_lon(track: Any) -> float:
    return M_PER_DEG_LAT * math.cos(math.radians(track.lat_deg))


SCENARIO = """
[scenario]
name = "adsb_intruder"
description = "one multirotor flies east; ADS-B traffic meets it head-on"
duration_s = 50.0

[airspace]
origin_lat_deg = 40.65974645776713
origin_lon_deg = -3.59689676974471
ground_elevation_amsl_m = 675.0

[[operations]]
id = "UAS1"
icao24 = "346617"
sys_id = 1
priority = 10
vehicle = "multirotor"
autopilot = "px4"
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 15.0
max_climb_rate_mps = 3.0
endurance_s = 1200.0
home = { east_m = 0.0, north_m = 0.0, alt_agl_m = 0.0 }
waypoints = [
    { east_m = 0.0, north_m = 0.0, alt_agl_m = 40.0 },
    { east_m = 400.0, north_m = 0.0, alt_agl_m = 40.0 },
]
"""


class SbsReceiver:
    """A dump1090-style SBS-1 feed: every line written goes to every connected client."""

    def __init__(self) -> None:
        self.writers: list[asyncio.StreamWriter] = []
        self.server: asyncio.Server | None = None
        self.port = 0

    async def start(self) -> None:
        async def handle(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
            self.writers.append(w)
            with contextlib.suppress(OSError):
                await r.read()
            self.writers.remove(w)
            w.close()

        self.server = await asyncio.start_server(handle, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]

    def send(self, *lines: str) -> None:
        for w in self.writers:
            w.write(("".join(f"{line}\r\n" for line in lines)).encode())

    async def close(self) -> None:
        for w in self.writers:
            w.close()
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()


async def _traffic(rt: Runtime, sbs: SbsReceiver) -> None:
    """Once UAS1 has a track: every 0.2 s (wall) the SBS aircraft, from 1.5 km ahead, and
    relayed ADSB_VEHICLE reports of the distant aircraft and of UAS1's own transponder."""
    link = rt.hub.link_names()[0]
    port = rt.hub.local_port(link)
    relay = mav.MAVLink(None, srcSystem=42, srcComponent=1)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    start: tuple[float, float, float] | None = None
    try:
        while True:
            own = rt.tracks().get("UAS1")  # type: ignore[call-overload]
            if own is None or own.updates < 5 or own.alt_amsl_m < 675.0 + 20.0:
                await asyncio.sleep(0.1)
                continue
            ve, vn, vu = own.vel_enu_mps
            now_s = rt.clock.now_s()
            if start is None:
                start = (now_s, own.lat_deg, own.lon_deg + HEADON_AHEAD_M / m_per_deg_lon(own))
            # head-on, same altitude, closing at HEADON_SPEED_MPS + the UAS's speed
            lon_deg = start[2] - HEADON_SPEED_MPS * (now_s - start[0]) / m_per_deg_lon(own)
            sbs.send(
                sbs_velocity(HEADON_ICAO, HEADON_SPEED_MPS / (1852.0 / 3600.0), 270.0, 0.0),
                sbs_position(
                    HEADON_ICAO, start[1], lon_deg, own.alt_amsl_m / 0.3048, callsign="HEADON"
                ),
            )
            track_deg = math.degrees(math.atan2(ve, vn)) % 360.0
            frames = [
                adsb_vehicle(relay, int(DISTANT_ICAO, 16), own.lat_deg + 0.027, own.lon_deg),
                adsb_vehicle(
                    relay,
                    int(OWN_ICAO, 16),
                    own.lat_deg,
                    own.lon_deg,
                    altitude_mm=round(own.alt_amsl_m * 1000.0),
                    hor_velocity_cms=round(math.hypot(ve, vn) * 100.0),
                    heading_cdeg=round(track_deg * 100.0),
                    ver_velocity_cms=round(vu * 100.0),
                    tslc_s=0,
                ),
            ]
            for f in frames:
                sock.sendto(f, ("127.0.0.1", port))
            await asyncio.sleep(0.2)
    finally:
        sock.close()


async def test_sbs_and_relayed_adsb_become_intruders_and_raise_intruder(tmp_path: Path) -> None:
    path = tmp_path / "adsb_intruder.toml"
    path.write_text(SCENARIO)
    sbs = SbsReceiver()
    await sbs.start()
    settings = dataclasses.replace(
        Settings(),
        adsb=AdsbConfig(
            enabled=True, host="127.0.0.1", sbs_port=sbs.port, avr_port=0, beast_port=0
        ),
    )
    seen: dict[str, Any] = {}
    tasks: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        seen["rt"] = rt
        tasks.append(asyncio.create_task(_traffic(rt, sbs)))

    options = RunOptions(
        speed=SPEED,
        headless=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        figures=False,
        lead_s=10.0,
        record_dir=tmp_path / "rec",
    )
    try:
        report = (await run_scenario(path, settings, options, on_runtime=on_runtime)).to_json()
    finally:
        for t in tasks:
            t.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await sbs.close()
    rt: Runtime = seen["rt"]
    headon, distant = f"icao:{HEADON_ICAO}", f"icao:{DISTANT_ICAO}"
    # intruder tracks named by ICAO address, sampled in the report and written to the store
    assert headon in report["tracks"] and distant in report["tracks"], list(report["tracks"])
    # UAS1's own transponder fused with its track: no intruder of its address
    assert f"icao:{OWN_ICAO}" not in report["tracks"]
    assert f"adsb:{OWN_ICAO}" in report["telemetry"], list(report["telemetry"])
    store = Store(tmp_path / "adsb_intruder.sqlite")
    try:
        history = store.track_history(headon)
        assert history and not history[-1].cooperative and history[-1].icao24 == HEADON_ICAO
        assert store.track_history(distant)
    finally:
        store.close()
    # the feed was counted
    (feed,) = report["adsb"]["feeds"].values()
    assert feed["positions"] >= 10 and feed["rejects"] == 0 and feed["connects"] == 1
    relay = report["adsb"]["mavlink_relay"]
    assert relay["measurements"] >= 20 and relay["invalid"] == 0
    # run --record: the link recorded as a .tlog; its replay tracks the relayed aircraft too
    (tlog,) = (tmp_path / "rec").glob("*.tlog")
    replayed = await replay_file(tlog)
    assert distant in replayed["tracks"] and not replayed["tracks"][distant]["cooperative"]
    assert "sysid:1" in replayed["tracks"], list(replayed["tracks"])
    assert replayed["counters"]["adsb_relay"]["measurements"] == relay["measurements"]
    # head-on at the same altitude: predicted inside the intruder minima -> INTRUDER, raised
    # before the aircraft is within them (it closes at ~45 m/s from 1.5 km)
    intruder = [t for t in rt.usm.threat_log if t.kind is ThreatKind.INTRUDER]
    assert intruder, [t.kind for t in rt.usm.threat_log]
    assert {t.intruder_id for t in intruder} == {headon}
    assert all(t.uas_ids == ("UAS1",) for t in intruder)
    first = intruder[0]
    assert first.closest_approach_m is not None and first.closest_approach_m < 150.0
    assert first.predicted_event_at_s is not None
    assert first.predicted_event_at_s - first.detected_at_s >= 10.0
    # EM proposes an avoidance through the prompt: closing at 45 m/s from 1.5 km leaves ~33 s,
    # enough to climb the intruder minima at the vehicle's climb rate (auto-accepted, flown)
    recs = [r for r in report["recommendations"] if r["threat_kind"] == "INTRUDER"]
    assert recs, report["escalations"]
    avoid = ("go_up", "go_down", "go_left", "go_right")
    accepted = [t for r in recs for _, t in r["history"] if t.startswith("accepted")]
    assert accepted and accepted[0].split(": ")[1].split(" ")[0] in avoid, accepted
    # the aircraft follows UAS1's altitude: whatever EM cannot avoid any more, it proposes
    # the safe command for; no escalation comes with nothing proposed
    for esc in report["escalations"]:
        assert "intruder" not in esc["text"] or "proposed" in esc["text"], esc


async def test_serve_tracks_sbs_and_relayed_aircraft_and_records_the_link(tmp_path: Path) -> None:
    sbs = SbsReceiver()
    await sbs.start()
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        adsb=AdsbConfig(
            enabled=True, host="127.0.0.1", sbs_port=sbs.port, avr_port=0, beast_port=0
        ),
    )
    stop = asyncio.Event()
    seen: dict[str, Any] = {}

    async def feed(rt: Runtime) -> None:
        relay = mav.MAVLink(None, srcSystem=42, srcComponent=1)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            port = rt.hub.local_port(rt.hub.link_names()[0])
            sock.sendto(adsb_vehicle(relay, int(DISTANT_ICAO, 16), 47.5, 8.6), ("127.0.0.1", port))
        lon_deg = 8.5456
        while f"icao:{HEADON_ICAO}" not in rt.tracks() or f"icao:{DISTANT_ICAO}" not in rt.tracks():
            lon_deg += 0.0002
            sbs.send(sbs_position(HEADON_ICAO, 47.3977, lon_deg, 1500.0))
            await asyncio.sleep(0.1)
        seen["track"] = rt.tracks()[f"icao:{HEADON_ICAO}"]  # type: ignore[index]
        seen["stats"] = rt.surveillance.stats()
        stop.set()

    tasks: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        tasks.append(asyncio.create_task(feed(rt)))

    try:
        code = await asyncio.wait_for(
            serve(
                settings,
                db_path=tmp_path / "utm.sqlite",
                operator=OperatorMode.NONE,
                headless=False,
                stop=stop,
                on_runtime=on_runtime,
                record_dir=tmp_path / "rec",
            ),
            timeout=20.0,
        )
    finally:
        for t in tasks:
            t.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await sbs.close()
    assert code == 0
    track = seen["track"]
    assert not track.cooperative and track.icao24 == HEADON_ICAO
    assert track.alt_amsl_m == pytest.approx(1500.0 * 0.3048, abs=5.0)
    (feed_stats,) = seen["stats"].values()
    assert feed_stats["positions"] >= 1 and feed_stats["up"] == 1
    # serve --record: the relayed frame is in the link's tlog (with our heartbeats, if any)
    (tlog,) = (tmp_path / "rec").glob("*.tlog")
    types = [m.get_type() for _, m in tlog_messages(tlog)]
    assert types.count("ADSB_VEHICLE") == 1 and set(types) <= {"ADSB_VEHICLE", "HEARTBEAT"}
