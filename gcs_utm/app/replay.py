"""Replay as a configuration of the service: recorded MAVLink packets and ADS-B measurements go
through the live service's parts, on a clock that runs on record time.

    recorded packet --> MavlinkHub (a receive-only replay link: the live receiver, decoder and
    per-vehicle dispatch) --> ReplayLog --> TrackingService --> Airspace snapshot
    --> MonitoringService (periodic) --> threats --> ReplayLog
    decoded ADS-B capture --> ReplayLog --> TrackingService

The parts are the ones :func:`gcs_utm.app.build_runtime` builds for ``serve`` and ``run``,
connected the same way; the operator side (USM, Emergency Management, the store, the
frontends) is left out: a replay only watches, nothing is sent to the recorded vehicles.

Time: every event is handed over when the clock reaches its record time (the record time is
the receipt time, as on a live link; capture times come from the vehicle-clock mapping of the
live hub). As fast as possible (``speed=None``) the replay runs on a
:class:`gcs_utm.clock.FastTimeLoop` with a :class:`~gcs_utm.clock.LoopClock` starting at the
first record, so the services' periodic tasks (tracking's batches, monitoring's cycles) run at
their record-time instants without waiting; with a speed factor on a
:class:`~gcs_utm.clock.ScaledClock`. At the end, what is pending is ingested and one last
monitoring cycle runs at the last record time.

The airspace frame is the scenario's, else the first position's (its altitude the frame's
ground elevation; 0 m for an ADS-B aircraft): events are looked at, without being handed
over, until the first position.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from adapters.mavlink import MavlinkHub, wire
from adapters.mavlink.transport import Address
from adapters.remoteid.ingest import RidIngest, telemetry_positions
from adapters.remoteid.tracks import RidTracks
from gcs_utm.clock import Clock, FastTimeLoop, LoopClock, ScaledClock
from gcs_utm.core.monitoring import Monitor
from gcs_utm.core.tracking import Tracker
from gcs_utm.geo import LocalFrame
from gcs_utm.model import AirspaceSnapshot, Geofence, Measurement, Operation
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.monitoring import MonitoringService
from gcs_utm.services.tracking import TrackingService
from gcs_utm.settings import Settings

from .replay_log import ReplayLog

_log = logging.getLogger(__name__)

ReplayEvent = tuple[float, bytes | Measurement]
"""(record t_s, a recorded MAVLink packet or a measurement decoded from a capture)."""

_YIELD_EVERY = 500  # events between yields to the loop when nothing waits in between


@dataclass(frozen=True, slots=True, kw_only=True)
class ReplayConfig:
    """The settings ([mavlink], [tracking], [monitoring], [remote_id] apply), and with a
    scenario its frame, operations and geofences; ``link``: the replay link's name."""

    settings: Settings = field(default_factory=Settings)
    frame: LocalFrame | None = None
    operations: tuple[Operation, ...] = ()
    geofences: tuple[Geofence, ...] = ()
    link: str = "tlog"

    def __post_init__(self) -> None:
        if self.operations and self.frame is None:
            raise ValueError("operations need the frame their plans are in")


@dataclass(slots=True, kw_only=True)
class ReplayRuntime:
    """Every built part of a replay, for its report."""

    clock: Clock
    frame: LocalFrame
    hub: MavlinkHub
    receive: Callable[[bytes, Address | None], None]
    airspace: Airspace
    tracking: TrackingService
    monitoring: MonitoringService
    rid_ingest: RidIngest
    rid_tracks: RidTracks
    log: ReplayLog
    framed: bool = True  # False: no position to put the frame at (reported as none)


def build_replay(config: ReplayConfig, clock: Clock, frame: LocalFrame) -> ReplayRuntime:
    """Build and connect the parts (see the module docstring); no task started."""
    s = config.settings
    log = ReplayLog(now_s=clock.now_s)
    tracker = Tracker(frame, s.tracking)
    airspace = Airspace()
    airspace.load(config.operations, config.geofences)
    tracking = TrackingService(
        tracker,
        clock,
        on_hazard=log.on_tracking_hazard,
        ingest_delay_s=s.tracking.ingest_delay_s,
    )
    tracking.set_operations(config.operations)
    log.submit = tracking.submit

    def snapshot(t_s: float) -> AirspaceSnapshot:
        log.on_cycle(tracker)
        return airspace.snapshot(t_s, tracking.snapshot)

    monitoring = MonitoringService(
        Monitor(frame, s.monitoring), snapshot, clock, log.on_threats, s.monitoring.period_s
    )
    hub = MavlinkHub(s.mavlink, clock, log)
    receive = hub.add_replay_link(config.link)
    rid_ingest = RidIngest(
        consistency_m=s.remote_id.consistency_m, position_of=telemetry_positions(hub)
    )
    rid_ingest.register(hub.remote_id)
    rid_tracks = RidTracks(
        lambda: rid_ingest.aircraft,
        lambda: airspace.operations.values(),  # noqa: PLW0108 - a property
    )
    return ReplayRuntime(
        clock=clock,
        frame=frame,
        hub=hub,
        receive=receive,
        airspace=airspace,
        tracking=tracking,
        monitoring=monitoring,
        rid_ingest=rid_ingest,
        rid_tracks=rid_tracks,
        log=log,
    )


def replay_blocking(
    config: ReplayConfig,
    events: Iterator[ReplayEvent],
    *,
    speed: float | None = None,
    on_event: Callable[[int], None] | None = None,
) -> ReplayRuntime | None:
    """:func:`replay` on an event loop of its own: a :class:`FastTimeLoop` as fast as
    possible (``speed=None``), an ordinary one at a speed factor."""
    factory = FastTimeLoop if speed is None else None
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(replay(config, events, speed=speed, on_event=on_event))


async def replay(
    config: ReplayConfig,
    events: Iterator[ReplayEvent],
    *,
    speed: float | None = None,
    on_event: Callable[[int], None] | None = None,
) -> ReplayRuntime | None:
    """Hand ``events`` (in time order) to the replay's parts at their record times and return
    the runtime (None without a single event). ``on_event(n)`` after each event."""
    if speed is not None and not speed > 0.0:
        raise ValueError(f"speed must be positive or None, got {speed}")
    looked, first_position = _until_first_position(events)
    if not looked:
        return None
    frame = config.frame or _frame_at(first_position)
    t0_s = looked[0][0]
    loop = asyncio.get_running_loop()
    if speed is None:
        if not isinstance(loop, FastTimeLoop):
            raise RuntimeError("replay as fast as possible runs on a FastTimeLoop")
        clock: Clock = LoopClock(loop, t0_s)
    else:
        clock = ScaledClock(speed, start_utc_s=t0_s)
    rt = build_replay(config, clock, frame)
    rt.framed = config.frame is not None or first_position is not None
    _log.info("frame origin %.6f, %.6f", frame.origin_lat_deg, frame.origin_lon_deg)
    await _play(rt, itertools.chain(looked, events), on_event)
    return rt


async def _play(
    rt: ReplayRuntime, events: Iterator[ReplayEvent], on_event: Callable[[int], None] | None
) -> None:
    clock = rt.clock
    tasks = [
        asyncio.create_task(rt.tracking.run(), name="tracking"),
        asyncio.create_task(rt.monitoring.run(), name="monitoring"),
    ]
    await asyncio.sleep(0)  # both running (tracking schedules its ingests once it runs)
    try:
        for n, (t_s, item) in enumerate(events, 1):
            wait_s = t_s - clock.now_s()
            if wait_s > 0.0:
                await clock.sleep(wait_s)
            elif n % _YIELD_EVERY == 0:
                await asyncio.sleep(0)
            if isinstance(item, bytes):
                rt.receive(item, None)
            else:
                rt.log.on_capture(item)
            if on_event is not None:
                on_event(n)
    finally:
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
    # what arrived since the last cycle, then a last cycle at the last record time
    await rt.tracking.step()
    threats = rt.monitoring.run_once(clock.now_s())
    if threats:
        await rt.log.on_threats(threats)


Position = tuple[float, float, float, bool]
"""A first position: (lat_deg, lon_deg, alt_amsl_m, from an aircraft)."""

_LOOK_AHEAD = 200_000  # events looked at for a first position, at most (they are kept)


def _until_first_position(
    events: Iterator[ReplayEvent],
) -> tuple[list[ReplayEvent], Position | None]:
    """The events up to the first position (taken from ``events``) and that position."""
    parser = wire.Parser()
    looked: list[ReplayEvent] = []
    for ev in events:
        looked.append(ev)
        item = ev[1]
        if not isinstance(item, bytes):
            return looked, (item.lat_deg, item.lon_deg, item.alt_amsl_m, True)
        for m in parser.feed(item, datagram=True):
            pos = _position(m)
            if pos is not None:
                return looked, pos
        if len(looked) >= _LOOK_AHEAD:
            _log.warning("no position in the first %d records: frame at 0, 0", _LOOK_AHEAD)
            break
    return looked, None


def _position(m: Any) -> Position | None:
    """The position of a GLOBAL_POSITION_INT or ADSB_VEHICLE (as the live handlers take it:
    an estimate, not 0, 0)."""
    mid = wire.msg_id(m)
    if mid == wire.GLOBAL_POSITION_INT and (m.lat or m.lon):
        return m.lat / 1e7, m.lon / 1e7, m.alt / 1000.0, False
    if mid == wire.ADSB_VEHICLE and (m.lat or m.lon):
        return m.lat / 1e7, m.lon / 1e7, m.altitude / 1000.0, True
    return None


def _frame_at(first: Position | None) -> LocalFrame:
    """The frame at the first position (0 m ground under an aircraft), else at 0, 0."""
    if first is None:
        return LocalFrame(0.0, 0.0)
    lat_deg, lon_deg, alt_amsl_m, aircraft = first
    return LocalFrame(lat_deg, lon_deg, ground_elevation_amsl_m=0.0 if aircraft else alt_amsl_m)


__all__ = [
    "ReplayConfig",
    "ReplayEvent",
    "ReplayRuntime",
    "build_replay",
    "replay",
    "replay_blocking",
]
