"""Every numeric setting at its extremes: ``config check`` either refuses the value with one
line naming the key, or ``serve``'s start works with it and tracks a vehicle (issue 32).

For each numeric key of the settings table: an absurd value (1e300, or 2**62 for an integer,
and their negatives) and the smallest and largest value the checks accept. A refused value
must be one ``ConfigError`` line naming the key; an accepted one is started in process the
way ``serve`` starts (the services built by :func:`build_runtime`, a MAVLink ``udpin`` link
bound, a vehicle's HEARTBEAT and GLOBAL_POSITION_INT datagrams sent to it, one tracking step,
one monitoring cycle) and must give a track at the vehicle's position."""

from __future__ import annotations

import asyncio
import dataclasses
import functools
import socket
import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mav

from gcs_utm.app.wiring import Persistence, build_runtime
from gcs_utm.clock import RealClock
from gcs_utm.config import ConfigError, limits
from gcs_utm.geo import LocalFrame
from gcs_utm.preflight import check_settings
from gcs_utm.settings import SECTIONS, Settings, settings_from_mapping
from gcs_utm.store import StoreWriter


def _numeric(cls: type[Any], prefix: str) -> Iterator[tuple[str, bool, dict[str, Any]]]:
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            yield from _numeric(tp, f"{prefix}{f.name}.")  # type: ignore[arg-type]
        elif tp in (int, float):
            yield f"{prefix}{f.name}", tp is int, dict(f.metadata)


NUMERIC = [item for name, cls in SECTIONS.items() for item in _numeric(cls, f"{name}.")]


def _mapping(key: str, value: float) -> dict[str, Any]:
    *tables, leaf = key.split(".")
    doc: dict[str, Any] = {}
    node = doc
    for t in tables:
        node = node.setdefault(t, {})
    node[leaf] = value
    return doc


def _load(key: str, value: float) -> Settings | str:
    """The settings with ``key = value`` as ``config check`` and ``serve`` load them, or the
    one line they refuse it with."""
    try:
        settings = settings_from_mapping(_mapping(key, value), source="extreme.toml")
        check_settings(settings, source="extreme.toml")
    except ConfigError as exc:
        return str(exc)
    return settings


def _vehicle_datagrams(frame: LocalFrame) -> list[bytes]:
    out = mav.MAVLink(None, srcSystem=7, srcComponent=1)
    heartbeat = out.heartbeat_encode(2, 12, 1 | 128, 4 << 16, 4, 3).pack(out)
    out.seq = 1
    position = out.global_position_int_encode(
        60_000,
        round(frame.origin_lat_deg * 1e7),
        round(frame.origin_lon_deg * 1e7),
        round((frame.ground_elevation_amsl_m + 50.0) * 1000),
        50_000,
        0,  # hovering: any accepted speed gate lets it through
        0,
        0,
        0,
    ).pack(out)
    return [heartbeat, position]


@functools.cache
def _frame(lat_deg: float, lon_deg: float, elevation_m: float) -> LocalFrame:
    return LocalFrame(lat_deg, lon_deg, elevation_m)  # ~90 ms of pyproj set-up: once


async def _starts_and_tracks(settings: Settings, writer: StoreWriter) -> None:
    """``serve``'s start with ``settings``, in process: a vehicle is tracked."""
    air = settings.airspace
    frame = _frame(air.origin_lat_deg, air.origin_lon_deg, air.ground_elevation_amsl_m)
    rt = build_runtime(settings, RealClock(), frame, Persistence(writer))
    try:
        link = await rt.hub.add_link("udpin:127.0.0.1:0")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
            for datagram in _vehicle_datagrams(frame):
                vehicle.sendto(datagram, ("127.0.0.1", rt.hub.local_port(link)))
        async with asyncio.timeout(5.0):
            while rt.usm.counters["measurements"] == 0:
                await asyncio.sleep(0.002)
        await rt.tracking.step()
        tracks, _predicted = rt.tracking.snapshot()
        rt.monitoring.run_once(rt.clock.now_s())
    finally:
        await rt.hub.close()
    assert len(tracks) == 1, tracks
    (track,) = tracks.values()
    assert abs(track.lat_deg - frame.origin_lat_deg) < 1e-3, track
    east_deg = (track.lon_deg - frame.origin_lon_deg + 180.0) % 360.0 - 180.0  # +-180 alike
    assert abs(east_deg) < 1e-3, track


def _extremes(integer: bool, meta: dict[str, Any]) -> list[float]:
    lo, hi, _ = limits(meta, integer=integer)
    absurd: float = 2**62 if integer else 1e300
    values = [absurd, -absurd, lo, hi]
    return [int(v) for v in values] if integer else values


@pytest.fixture(scope="module")
def shared_writer(tmp_path_factory: pytest.TempPathFactory) -> Iterator[StoreWriter]:
    writer = StoreWriter(tmp_path_factory.mktemp("extremes") / "db.sqlite3")
    yield writer
    writer.close()


@pytest.mark.parametrize(("key", "integer", "meta"), NUMERIC, ids=[k for k, _, _ in NUMERIC])
def test_a_numeric_setting_at_its_extremes_is_refused_or_works(
    key: str, integer: bool, meta: dict[str, Any], tmp_path: Path, shared_writer: StoreWriter
) -> None:
    for value in _extremes(integer, meta):
        loaded = _load(key, value)
        if isinstance(loaded, str):
            # one line naming the key (a conflict with another key names both)
            assert "\n" not in loaded and key.rsplit(".", 1)[1] in loaded, (value, loaded)
            continue
        own = key.startswith("store.")  # the store's own settings: a writer of its own
        writer = StoreWriter(tmp_path / "db.sqlite3", loaded.store) if own else shared_writer
        try:
            asyncio.run(_starts_and_tracks(loaded, writer))
        except Exception as exc:
            pytest.fail(f"{key} = {value!r}: accepted, but the start failed: {exc!r}")
        finally:
            if own:
                writer.close()
