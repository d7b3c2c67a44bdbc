"""``run --record DIR`` replayed: a built-in vehicle flies while an SBS-1 receiver (a TCP
server on loopback, ephemeral port) reports an aircraft; the service records its MAVLink link
as tlogs and the feed raw, both rotated by [record] max_file_mb into several files; ``gcs-utm
replay DIR`` (with the scenario, so the vehicle is associated with its operation) gives back
the same tracks: the same track ids and last update times (within 1 s), the aircraft's last
position within 1 cm (the replay decodes the recorded bytes at their recorded receipt times,
so its measurements are the live ones; measured: 2e-5 m, the microsecond rounding of the
times), the vehicle's within 5 m, one second of its flight at 5 m/s (the replay's hub times
telemetry as the live hub did: by the vehicle's clock mapped on the recorded receipt
times)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import shutil
from pathlib import Path
from typing import Any

import pytest

from adapters.adsb.config import AdsbConfig
from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, RunOptions, Runtime, run_scenario, serve
from gcs_utm.cli.replay import scenario_config
from gcs_utm.cli.replay_inputs import discover, replay_inputs
from gcs_utm.geo import haversine_m
from gcs_utm.services.record_config import RecordConfig
from gcs_utm.settings import Settings
from tests.adsb.sbs_lines import sbs_position, sbs_velocity
from tests.e2e.test_adsb_service import SCENARIO, SbsReceiver

pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(120)]

SPEED = 5.0
ICAO = "a1b2c3"
AIRCRAFT_FOR_S = 25.0  # simulated seconds the receiver reports the aircraft, then silence


async def _aircraft(rt: Runtime, sbs: SbsReceiver) -> None:
    """2 km north of the origin at 1,500 ft, flying east at 50 m/s (about 100 kt)."""
    t0 = rt.clock.now_s()
    while (t := rt.clock.now_s() - t0) < AIRCRAFT_FOR_S:
        lon_deg = -3.59689676974471 + 50.0 * t / 84_400.0
        sbs.send(
            sbs_velocity(ICAO, 97.2, 90.0, 0.0),
            sbs_position(ICAO, 40.6777, lon_deg, 1500.0, callsign="REC1"),
        )
        await asyncio.sleep(0.2)


async def test_recorded_run_replays_to_the_same_tracks(tmp_path: Path) -> None:
    scenario = tmp_path / "adsb_intruder.toml"
    scenario.write_text(SCENARIO)
    rec_dir = tmp_path / "rec"
    sbs = SbsReceiver()
    await sbs.start()
    settings = dataclasses.replace(
        Settings(),
        adsb=AdsbConfig(
            enabled=True, host="127.0.0.1", sbs_port=sbs.port, avr_port=0, beast_port=0
        ),
        record=RecordConfig(max_file_mb=0.001),  # 1 kB: several files per stream
    )
    seen: dict[str, Any] = {}
    tasks: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        seen["rt"] = rt
        tasks.append(asyncio.create_task(_aircraft(rt, sbs)))

    options = RunOptions(
        speed=SPEED,
        headless=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        figures=False,
        lead_s=10.0,
        duration_s=40.0,
        record_dir=rec_dir,
    )
    try:
        await run_scenario(scenario, settings, options, on_runtime=on_runtime)
    finally:
        for t in tasks:
            t.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await sbs.close()
    live = seen["rt"].tracking.tracker.tracks()  # as last updated (not predicted to now)
    tlogs = sorted(rec_dir.glob("*.tlog"))
    captures = sorted(rec_dir.glob("adsb-sbs_127.0.0.1_*.sbs"))
    assert len(tlogs) >= 2 and len(captures) >= 2, sorted(p.name for p in rec_dir.iterdir())
    assert all(p.with_name(p.name + ".times").is_file() for p in captures)

    inputs = discover([rec_dir])
    assert len(inputs.feeds) == 1 and inputs.feeds[0].pieces == tuple(captures)
    report = await asyncio.to_thread(
        replay_inputs, inputs, config=scenario_config(inputs, scenario)
    )

    assert set(report["tracks"]) == set(live) == {"UAS1", f"icao:{ICAO}"}
    (feed,) = report["counters"]["adsb_feeds"].values()
    live_feed = seen["rt"].surveillance.stats()[f"sbs:127.0.0.1:{sbs.port}"]
    assert feed["positions"] == live_feed["positions"] >= 20  # ~5 a simulated second
    assert feed["rejects"] == live_feed["rejects"] == 0
    for tid, tol_m in ((f"icao:{ICAO}", 0.01), ("UAS1", 5.0)):
        got = report["tracks"][tid]["last_position"]
        want = live[tid]
        error_m = haversine_m(got["lat_deg"], got["lon_deg"], want.lat_deg, want.lon_deg)
        assert error_m < tol_m, (tid, error_m, got, want)
        assert report["tracks"][tid]["last_t_s"] == pytest.approx(want.t_s, abs=1.0), tid
        assert got["alt_amsl_m"] == pytest.approx(want.alt_amsl_m, abs=tol_m), tid
    assert not report["tracks"][f"icao:{ICAO}"]["cooperative"]
    assert report["tracks"]["UAS1"]["cooperative"]


async def test_serve_survives_its_recording_folder_vanishing(tmp_path: Path) -> None:
    """Mid-run the recording folder disappears (as a full or unmounted disk would fail the
    next file): the failure is logged and written to the USM's event log, and ``serve``
    carries on tracking the feed."""
    rec_dir = tmp_path / "rec"
    sbs = SbsReceiver()
    await sbs.start()
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        adsb=AdsbConfig(
            enabled=True, host="127.0.0.1", sbs_port=sbs.port, avr_port=0, beast_port=0
        ),
        record=RecordConfig(max_file_mb=0.001),  # a new file every few lines
    )
    stop = asyncio.Event()
    seen: dict[str, Any] = {}

    async def feed(rt: Runtime) -> None:
        lon_deg = 8.5456
        for i in range(400):
            lon_deg += 0.0002
            sbs.send(sbs_position(ICAO, 47.3977, lon_deg, 1500.0))
            if i == 20:
                shutil.rmtree(rec_dir)
            failed = [e for e in rt.usm.events if e.kind == "recording"]
            if failed and "updates" not in seen:
                seen["event"] = failed[0].text
                seen["updates"] = rt.tracking.tracker.tracks()[f"icao:{ICAO}"].updates
            elif (
                failed
                and rt.tracking.tracker.tracks()[f"icao:{ICAO}"].updates > seen["updates"] + 5
            ):
                break  # still tracking after the failure
            await asyncio.sleep(0.05)
        seen["final"] = rt.tracking.tracker.tracks()[f"icao:{ICAO}"].updates
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
                record_dir=rec_dir,
            ),
            timeout=40.0,
        )
    finally:
        for t in tasks:
            t.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await sbs.close()
    assert code == 0
    assert "recording of adsb-sbs:127.0.0.1:" in seen["event"]
    assert seen["event"].endswith("the service carries on")
    assert seen["final"] > seen["updates"] + 5  # tracked on after the failure
