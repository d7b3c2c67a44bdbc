"""``serve``: the long-running service. Links from the settings, a persistent store (what one
run filed is the airspace of the next), wired by the same builder as scenario runs."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import os
import signal
import socket
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

from gcs_utm.clock import Clock, RealClock, ScaledClock
from gcs_utm.cluster.commands import CommandGate
from gcs_utm.cluster.exchange import RegionExchange, RemoteTrack
from gcs_utm.cluster.member import region_map_of
from gcs_utm.cluster.node import ClusterNode
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.cluster.regions import RegionError
from gcs_utm.config import ConfigError
from gcs_utm.geo import LocalFrame
from gcs_utm.model import Geofence, Operation
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.recorder import check_folder, record_links
from gcs_utm.settings import Settings
from gcs_utm.store import StoreConfig, StoreError, StoreWriter, describe, is_postgres, open_store

from .restart import start_review
from .stopping import Stopping
from .wiring import (
    FrontendOptions,
    Frontends,
    Persistence,
    Runtime,
    attach_frontends,
    build_runtime,
    start_service_tasks,
)

_log = logging.getLogger(__name__)


def check_cluster(settings: Settings, location: str | Path) -> None:
    """``serve --cluster`` needs the shared database and a region on the grid."""
    if not is_postgres(location):
        raise StoreError("serve --cluster: set [store] url to the shared postgresql:// database")
    if settings.cluster.region:
        try:
            region_map_of(settings.cluster).cell(settings.cluster.region)
        except RegionError as exc:
            raise StoreError(f"[cluster] {exc}") from exc


async def join_cluster(
    rt: Runtime,
    location: str | Path,
    stop: asyncio.Event,
    failed: list[str],
    policy: OwnershipPolicy,
    *,
    gateway: MqttGateway | None = None,
) -> ClusterNode:
    """This runtime as a cluster member: checks the region map (a differing one is refused);
    the member task and the region exchange (on the [mqtt] broker) start with the service
    tasks. ``gateway``: the MQTT interface, whose answers, plans and commands one instance
    carries out and answers (gcs_utm.cluster.inbound)."""
    settings = rt.settings.cluster
    instance = settings.instance or f"{socket.gethostname()}-{os.getpid()}"

    def fail(why: str) -> None:
        failed.append(why)
        stop.set()

    node: ClusterNode

    async def on_tracks(tracks: list[RemoteTrack]) -> None:
        await node.on_remote_tracks(tracks)

    exchange = RegionExchange(
        rt.settings.mqtt,
        region_map_of(settings),
        client_id=f"{rt.settings.mqtt.topic_prefix}-cluster-{instance}",
        on_tracks=on_tracks,
    )
    node = ClusterNode(
        location,
        settings,
        instance=instance,
        epoch=rt.store.epoch,
        frame=rt.frame,
        clock=rt.clock,
        airspace=rt.airspace,
        tracking=rt.tracking,
        usm=rt.usm,
        record=rt.store.record,
        on_fail=fail,
        policy=policy,
        exchange=exchange,
        tracks=rt.tracks,
        emergency=rt.emergency,
        heard=rt.usm.statuses_by_sys_id,  # the vehicles heard, by system id
    )
    rt.store.writer.set_fence(node.fence)  # region-owned rows carry the lease generation
    rt.usm.vehicle_ops.owns = node.files  # behind a router: only our regions' vehicles
    # an operator's command: carried out by the owner of the UAS's region only
    rt.usm.operator_commands.gate = CommandGate(node.member, policy, rt.frame, node.may_act)
    if gateway is not None:
        gateway.arbiter = node.inbound
    try:
        await node.member.start()
    except RegionError as exc:
        await node.member.close()
        raise StoreError(str(exc)) from exc
    return node


def _writer_config(settings: Settings, cluster: bool) -> StoreConfig:
    """A cluster member's writer statements (and a stall inside its transaction) are bounded
    by ``lease_s``: a write holds its fence's lock on a lease row (``FOR SHARE``) until it
    commits, so a takeover of that region never waits longer than that on a stuck writer."""
    config = settings.store
    bound_s = settings.cluster.lease_s
    if not cluster or 0.0 < config.statement_timeout_s <= bound_s:
        return config
    return dataclasses.replace(config, statement_timeout_s=bound_s)


def _stored_airspace(
    settings: Settings, db_path: Path, *, cluster: bool
) -> tuple[str | Path, list[Operation], list[Geofence], float | None]:
    """Where the store is ([store] url, a shared PostgreSQL database, replaces the SQLite
    file when set), the operations and active geofences it holds, and its latest time. A
    cluster member's operations come with the regions it gains (gcs_utm.cluster.node)."""
    location: str | Path = settings.store.url or db_path
    if cluster:
        check_cluster(settings, location)
    with open_store(location, busy_timeout_s=settings.store.busy_timeout_s) as reader:
        operations = [] if cluster else reader.load_operations()
        geofences = reader.load_geofences(active_only=True)
        latest_t_s = reader.latest_t_s()
    return location, operations, geofences, latest_t_s


def _service_clock(speed: float, latest_t_s: float | None) -> Clock:
    """Wall time at speed 1. At a speed factor the clock runs ``speed`` times faster than the
    wall clock and, on a store an earlier life wrote, starts where the store's latest time
    is when that is ahead of the wall clock (it is, after a life at a speed above 1): started
    from the wall clock, a restarted service's times went back (its plans, threats and
    track history interleaved with the previous life's)."""
    if speed == 1.0:
        return RealClock()
    now_s = time.time()
    return ScaledClock(speed, start_utc_s=max(now_s, latest_t_s or now_s))


async def _open_links(rt: Runtime) -> None:
    """Open the ``[mavlink]`` links; one that cannot be (taken since the start's
    check_resources) is one ConfigError line (the runtime's teardown closes what is open)."""
    for i, link in enumerate(rt.settings.mavlink.links):
        try:
            await rt.hub.add_link(link)
        except OSError as exc:
            raise ConfigError(
                "serve", f"mavlink.links[{i}]", f"{link!r} cannot be opened: {exc}"
            ) from exc


async def serve(
    settings: Settings,
    *,
    db_path: Path,
    operator: str,
    headless: bool,
    stop: asyncio.Event | None = None,
    on_runtime: Callable[[Runtime], Awaitable[None]] | None = None,
    speed: float = 1.0,
    record_dir: Path | None = None,
    cluster: bool = False,
) -> int:
    """Long-running service: links from config, persistent store; restart resumes. Runs until
    SIGINT/SIGTERM (or ``stop`` is set). ``speed`` > 1 matches SITL vehicles running faster
    than real time: the service's clock then advances ``speed`` simulated seconds per second.
    ``cluster``: a member of several instances sharing the ``[store] url`` database
    (docs/scale-out.md); returns 3 when a region is lost (fail-stop)."""
    if record_dir is not None:  # refused before anything starts (RecordError)
        check_folder(record_dir, settings.record)
    location, operations, geofences, latest_t_s = _stored_airspace(
        settings, db_path, cluster=cluster
    )
    clock = _service_clock(speed, latest_t_s)
    frame = LocalFrame(
        settings.airspace.origin_lat_deg,
        settings.airspace.origin_lon_deg,
        settings.airspace.ground_elevation_amsl_m,
    )
    # a PostgreSQL outage at stop leaves the writes not yet taken in a local journal
    pending = Path(settings.store.journal) if is_postgres(location) else None
    store = Persistence(StoreWriter(location, _writer_config(settings, cluster), journal=pending))
    policy = OwnershipPolicy() if cluster else None
    rt = build_runtime(settings, clock, frame, store, policy=policy)
    async with rt:  # whatever fails from here on, what was started is torn down
        store.writer.on_event = lambda text: rt.usm.log_event("store", text)
        rt.recorder = record_links(
            rt.hub,
            record_dir,
            settings.record,
            surveillance=rt.surveillance,
            on_failure=lambda text: rt.usm.log_event("recording", text),
        )
        rt.airspace.load(operations, geofences)
        rt.tracking.set_operations(operations)
        _log.info(
            "resumed %d operations and %d geofences from %s",
            len(operations),
            len(geofences),
            describe(location),
        )
        await _open_links(rt)
        frontends = attach_frontends(rt, FrontendOptions(operator=operator, headless=headless))
        stop = stop or asyncio.Event()
        failed: list[str] = []
        node = (
            await join_cluster(rt, location, stop, failed, policy, gateway=frontends.gateway)
            if policy
            else None
        )
        if on_runtime is not None:
            await on_runtime(rt)
        await _serve_until_stop(
            rt, frontends, node, location, stop=stop, failed=failed, cluster=cluster
        )
    print("gcs-utm serve: stopped", *failed, file=sys.stderr)
    return 3 if failed else 0


async def _serve_until_stop(
    rt: Runtime,
    frontends: Frontends,
    node: ClusterNode | None,
    location: str | Path,
    *,
    stop: asyncio.Event,
    failed: list[str],
    cluster: bool,
) -> None:
    """The service tasks until ``stop`` (SIGINT, SIGTERM, the dashboard's end, a lost
    region: ``failed``), then the runtime's bounded stop."""
    loop = asyncio.get_running_loop()
    stopping: Stopping | None = None
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    try:
        async with asyncio.TaskGroup() as tg:
            tasks = start_service_tasks(tg, rt, frontends)
            if node is not None:
                tasks.append(tg.create_task(node.run(), name="cluster"))
            tasks.extend(start_review(tg, rt, location, cluster=cluster))
            for t in tasks:
                if t.get_name() == "dashboard":
                    t.add_done_callback(lambda _t: stop.set())
            await stop.wait()
            stopping = Stopping(fenced=bool(failed))
            if await stopping.cancel(tasks):  # some task ignores its cancellation
                await rt.close(stopping)
                stopping.exit_now(3 if failed else 1, " ".join(["gcs-utm serve: stopped", *failed]))
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.remove_signal_handler(sig)
        await rt.close(stopping or Stopping(fenced=bool(failed)))
