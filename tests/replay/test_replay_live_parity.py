"""A replayed tlog goes through the live hub's per-message handling: the same messages give
the same vehicle home (HOME_POSITION) and height above it, replayed or received on a link."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path
from typing import Any

import pytest
from replay_helpers import T0_S

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.tlog import TlogWriter
from gcs_utm.cli.replay import replay_file
from gcs_utm.clock import ManualClock
from gcs_utm.model import SysId
from tests.mavlink.conftest import Sink

HOME = (47.3977419, 8.5455938, 488.25)  # lat_deg, lon_deg, alt_amsl_m
FLY_ALT_AMSL_M = 520.5


def _packets() -> list[tuple[float, bytes]]:
    """PX4 quadrotor: HEARTBEAT, HOME_POSITION, then positions climbing to 32.25 m above
    home, written with pymavlink (an implementation independent of ours)."""
    enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    out: list[tuple[float, bytes]] = []
    lat_e7, lon_e7, home_mm = round(HOME[0] * 1e7), round(HOME[1] * 1e7), round(HOME[2] * 1e3)
    for k in range(6):
        t = T0_S + k
        hb = enc.heartbeat_encode(2, 12, 129, 4 << 16 | 4 << 24, 4)
        out.append((t, bytes(hb.pack(enc))))
        if k == 1:
            q = [1.0, 0.0, 0.0, 0.0]
            home = enc.home_position_encode(lat_e7, lon_e7, home_mm, 0, 0, 0, q, 0, 0, 0)
            out.append((t + 0.1, bytes(home.pack(enc))))
        alt_mm = round((HOME[2] + (FLY_ALT_AMSL_M - HOME[2]) * k / 5) * 1e3)
        gp = enc.global_position_int_encode(k * 1000 + 500, lat_e7, lon_e7, alt_mm, 0, 0, 0, 0, 0)
        out.append((t + 0.5, bytes(gp.pack(enc))))
    return out


async def _live(packets: list[tuple[float, bytes]]) -> tuple[Any, float]:
    """The same packets into a live hub (UDP link, one sender): its home and last altitude."""
    sink = Sink()
    clock = ManualClock(T0_S)
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), health_period_s=3600.0)
    hub = MavlinkHub(cfg, clock, sink)
    await hub.start()
    try:
        link = next(iter(hub._links.values()))
        for t, data in packets:
            clock.set(t)
            hub._on_chunk(link, data, ("10.0.0.1", 14550))
        home = hub.state(SysId(1)).home
        assert home is not None and sink.statuses[-1].home == home
        return home, sink.measurements[-1].alt_amsl_m
    finally:
        await hub.close()


def test_replayed_home_position_gives_the_live_home_and_height(tmp_path: Path) -> None:
    packets = _packets()
    path = tmp_path / "home.tlog"
    with TlogWriter(path) as w:
        for t, data in packets:
            w.write(t, data)
    report = asyncio.run(replay_file(path))
    live_home, live_alt_amsl_m = asyncio.run(_live(packets))
    assert (live_home.lat_deg, live_home.lon_deg, live_home.alt_amsl_m) == pytest.approx(HOME)
    [v] = report["vehicles"]
    assert v["home"] == {
        "lat_deg": live_home.lat_deg,
        "lon_deg": live_home.lon_deg,
        "alt_amsl_m": live_home.alt_amsl_m,
    }
    live_height_m = live_alt_amsl_m - live_home.alt_amsl_m
    assert live_height_m == pytest.approx(FLY_ALT_AMSL_M - HOME[2], abs=1e-3)
    assert v["last_height_above_home_m"] == pytest.approx(live_height_m, abs=1e-3)
    assert report["counters"]["handler_errors"] == 0
