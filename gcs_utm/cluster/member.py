"""The cluster member task: holds this instance's regions and takes over orphaned ones.

Every ``renew_s`` (its own connection on its own thread, never behind the store writer's
queue of track batches nor behind the event loop, so neither a busy writer nor a long
monitoring cycle can cost a lease):
1. renew each region held; one that cannot be renewed is *lost* (``on_lost``): an instance
   that cannot reach the database for ``lease_s`` stops deciding for its regions, because a
   standby may hold them by then. Self-fencing runs on this instance's monotonic clock: a
   region's *deadline* is ``lease_s`` after the moment its last confirmed renewal was *sent*
   (the database stamps the expiry later than that, so the deadline never falls after the
   expiry a standby sees); :meth:`ClusterMember.expired` is the cheap local check the node
   makes before every decision and every command, and a round first gives up every region
   whose deadline passed (a stall, a slow renewal), whatever the database would answer now;
2. claim the configured ``region`` (the preferred owner claims it at once);
3. as a standby, take over a region whose lease has expired (its owner died or was cut
   off), and one never claimed once it has been seen free for ``lease_s`` (which gives its
   configured owner the head start at cluster start).
Every connection of the member runs under a statement timeout of ``lease_s`` (a renewal or a
read that takes longer is worthless: the lease has run out by then) and TCP keepalive; the
read connection is checked (a round trip) every round, so a standby that holds nothing and
never reads finds a connection broken by a PostgreSQL restart before a takeover needs it. A
region whose takeover cannot be loaded is handed back (:meth:`ClusterMember.drop`): released
on the next round, and taken again by a later one.
A region gained calls ``on_gained`` (the instance then loads that region's operations,
geofences and pending recommendations from the store, :mod:`gcs_utm.cluster.resume`). Stopping
releases every lease, so a clean shutdown hands the regions over at once.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import queue
import threading
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

from gcs_utm.cluster import lease as leases_
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.cluster.lease import Lease
from gcs_utm.cluster.regions import RegionMap
from gcs_utm.store import StoreBase, StoreError, open_store

_log = logging.getLogger(__name__)

RegionCallback = Callable[[str, Lease | None], Awaitable[None]]


def region_map_of(config: ClusterConfig) -> RegionMap:
    return RegionMap(
        west_m=config.west_m,
        south_m=config.south_m,
        cell_m=config.cell_m,
        columns=config.columns,
        rows=config.rows,
        halo_m=config.halo_m,
    )


class ClusterMember:
    """One instance's regions. ``holder`` names this instance life in the lease rows.

    The lease rounds run on a thread of their own with their own connection: a stalled event
    loop (a long monitoring cycle) must not delay a renewal and cost a region. Gains and
    losses are handed to the loop, where ``on_gained``/``on_lost`` run in order. ``owned`` is
    replaced, never mutated, so the loop reads a consistent mapping."""

    def __init__(
        self,
        location: str | Path,
        config: ClusterConfig,
        *,
        instance: str,
        epoch: int,
        on_gained: RegionCallback,
        on_lost: RegionCallback,
    ) -> None:
        self.config = config
        self.map = region_map_of(config)
        if config.region:
            self.map.cell(config.region)  # raises RegionError for a region off the map
        self.instance = instance
        self.epoch = epoch
        self.holder = f"{instance}#{epoch}"
        self._location = location
        self._on_gained = on_gained
        self._on_lost = on_lost
        self.owned: dict[str, Lease] = {}
        # regions lost (not renewed in time, taken over): read by the loop's may_act before
        # the loss event reaches it
        self.lost: list[str] = []
        self._renewed_mono: dict[str, float] = {}
        self._free_since_mono: dict[str, float] = {}
        self._lease_db: StoreBase | None = None
        self._read_db: StoreBase | None = None
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="cluster-read")
        self._stop = threading.Event()
        self._closed = False
        self._dropped: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._ping_pending = False
        # region -> holder of its live lease as the last round read it (replaced, never
        # mutated: the loop reads it to name another instance, e.g. in a refusal)
        self.holders: dict[str, str] = {}

    def _open(self) -> StoreBase:
        """A connection of the member: connect and every statement bounded by ``lease_s``."""
        bound_s = self.config.lease_s
        return open_store(self._location, busy_timeout_s=bound_s, statement_timeout_s=bound_s)

    # ---- reads for the node, on their own thread and connection ------------------------------
    def _reader(self) -> StoreBase:
        if self._closed:  # a read queued behind close() must not open a connection nobody closes
            raise StoreError("cluster member closed")
        if self._read_db is None or getattr(self._read_db, "broken", False):
            if self._read_db is not None:
                self._read_db.close()
            self._read_db = self._open()
        return self._read_db

    def _ping(self) -> None:
        """On the read thread: a round trip on the read connection (:meth:`StoreBase.ping`);
        a broken one is closed here, so the next read opens a new one instead of failing on
        the old."""
        try:
            if self._closed:
                return
            self._reader().ping()
        except StoreError as exc:
            _log.warning("cluster: read connection broken, reconnecting: %s", exc)
            if self._read_db is not None:
                db, self._read_db = self._read_db, None
                db.close()
        finally:
            self._ping_pending = False

    def _check_reader(self) -> None:
        """Queue a check of the read connection behind the reads (one at a time)."""
        if self._closed or self._ping_pending:
            return
        self._ping_pending = True
        try:
            self._pool.submit(self._ping)
        except RuntimeError:  # the pool was shut down by close()
            self._ping_pending = False

    def drop(self, region_id: str) -> None:
        """Hand a region back (its takeover could not be loaded): the next round releases its
        lease and forgets it, and a later round may take it again."""
        self._dropped.put(region_id)

    async def read(self, fn: Callable[[StoreBase], object]) -> object:
        """Run ``fn`` on the member's read connection (off the loop)."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, lambda: fn(self._reader()))

    async def start(self) -> None:
        """Check (or file) the region map; raises RegionError when the store's differs."""
        await self.read(lambda s: leases_.publish_map(s, self.map))

    # ---- one round, on the lease thread ---------------------------------------------------------
    def _leases(self) -> StoreBase:
        if self._lease_db is None or getattr(self._lease_db, "broken", False):
            if self._lease_db is not None:
                self._lease_db.close()
            self._lease_db = self._open()
        return self._lease_db

    def round(self) -> list[tuple[str, str, Lease | None]]:
        """Renew, claim, take over: one round; returns the (event, region, lease) changes."""
        events: list[tuple[str, str, Lease | None]] = []
        self._check_reader()
        self._release_dropped()
        try:
            db = self._leases()
            snapshot = leases_.leases(db)
            now_db = db.now_unix_s()
        except StoreError as exc:
            _log.warning("cluster: lease table unreachable: %s", exc)
            return self._fence()
        self.holders = {r: x.holder for r, x in snapshot.items() if x.expires_unix_s > now_db}
        for region_id in self.expired():  # past its deadline: fenced, whatever comes next
            events += self._lose(region_id, "lease deadline passed before a renewal")
        for region_id in [*self.owned, *self._candidates(snapshot, now_db)]:
            events += self._try(region_id)
        return events

    def _release_dropped(self) -> None:
        while True:
            try:
                region_id = self._dropped.get_nowait()
            except queue.Empty:
                return
            if region_id not in self.owned:
                continue
            self.owned = {r: lease for r, lease in self.owned.items() if r != region_id}
            self._renewed_mono = {r: t for r, t in self._renewed_mono.items() if r != region_id}
            try:
                leases_.release(self._leases(), region_id, self.holder)
            except StoreError as exc:  # it expires by itself
                _log.warning("cluster: release of %s failed: %s", region_id, exc)
            _log.warning("cluster: %s handed region %s back", self.holder, region_id)

    def _candidates(self, snapshot: dict[str, Lease], now_db: float) -> list[str]:
        out = []
        mono = time.monotonic()
        for region_id in self.map.ids():
            if region_id in self.owned:
                continue
            row = snapshot.get(region_id)
            if region_id == self.config.region:
                if row is None or row.expires_unix_s <= now_db or row.holder == self.holder:
                    out.append(region_id)
                continue
            if not self.config.standby:
                continue
            if row is not None and row.expires_unix_s <= now_db:
                out.append(region_id)  # an owner existed and stopped renewing
            elif row is None:
                first = self._free_since_mono.setdefault(region_id, mono)
                if mono - first >= self.config.lease_s:
                    out.append(region_id)
        return out

    def _try(self, region_id: str) -> list[tuple[str, str, Lease | None]]:
        sent_mono = time.monotonic()  # before the request: the deadline is measured from here
        try:
            got = leases_.acquire(
                self._leases(), region_id, self.holder, self.epoch, self.config.lease_s
            )
        except StoreError as exc:
            _log.warning("cluster: lease of %s not renewed: %s", region_id, exc)
            return self._fence()
        if got is None:
            if region_id in self.owned:
                return self._lose(region_id, "held by another instance")
            return []
        self._renewed_mono = {**self._renewed_mono, region_id: sent_mono}
        gained = region_id not in self.owned
        self.owned = {**self.owned, region_id: got}
        if not gained:
            return []
        _log.info(
            "cluster: %s holds region %s (generation %d)", self.holder, region_id, got.generation
        )
        return [("gained", region_id, got)]

    def _fence(self) -> list[tuple[str, str, Lease | None]]:
        """Regions not renewed for ``lease_s`` are given up here: another may hold them."""
        mono = time.monotonic()
        out: list[tuple[str, str, Lease | None]] = []
        for region_id in list(self.owned):
            if mono - self._renewed_mono.get(region_id, mono) >= self.config.lease_s:
                out += self._lose(region_id, "lease not renewed in time")
        return out

    def deadline_mono(self, region_id: str) -> float | None:
        """When this life stops holding ``region_id`` on the local monotonic clock: ``lease_s``
        after its last confirmed renewal was sent (None: not held)."""
        sent = self._renewed_mono.get(region_id)
        if sent is None or region_id not in self.owned:
            return None
        return sent + self.config.lease_s

    def expired(self, now_mono: float | None = None) -> list[str]:
        """The regions held whose deadline has passed (thread-safe, no I/O): such a region
        may already be another instance's."""
        now = time.monotonic() if now_mono is None else now_mono
        renewed = self._renewed_mono
        return [r for r in self.owned if now >= renewed.get(r, float("-inf")) + self.config.lease_s]

    def _lose(self, region_id: str, why: str) -> list[tuple[str, str, Lease | None]]:
        self.lost = [*self.lost, region_id]  # before owned: a reader never sees neither
        self.owned = {r: lease for r, lease in self.owned.items() if r != region_id}
        _log.warning("cluster: %s lost region %s: %s", self.holder, region_id, why)
        return [("lost", region_id, None)]

    def _lease_thread(
        self, loop: asyncio.AbstractEventLoop, events: asyncio.Queue[tuple[str, str, Lease | None]]
    ) -> None:
        while not self._stop.is_set():
            started = time.monotonic()
            for event in self.round():
                loop.call_soon_threadsafe(events.put_nowait, event)
            self._stop.wait(max(0.0, self.config.renew_s - (time.monotonic() - started)))
        for region_id in list(self.owned):  # a clean stop hands the regions over at once
            try:
                leases_.release(self._leases(), region_id, self.holder)
            except StoreError as exc:
                _log.warning("cluster: release of %s failed: %s", region_id, exc)
        self.owned = {}
        if self._lease_db is not None:
            self._lease_db.close()
            self._lease_db = None

    # ---- the task -------------------------------------------------------------------------
    async def run(self) -> None:
        """Lease rounds every ``renew_s`` on the lease thread, their gains and losses handled
        here in order, until cancelled; then every lease is released."""
        loop = asyncio.get_running_loop()
        events: asyncio.Queue[tuple[str, str, Lease | None]] = asyncio.Queue()
        self._stop.clear()
        thread = threading.Thread(
            target=self._lease_thread, args=(loop, events), name="cluster-lease", daemon=True
        )
        thread.start()
        try:
            while True:
                kind, region_id, lease = await events.get()
                if kind == "gained":
                    await self._on_gained(region_id, lease)
                else:
                    await self._on_lost(region_id, lease)
        finally:
            self._stop.set()
            await asyncio.shield(loop.run_in_executor(None, thread.join))
            await asyncio.shield(self.close())

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        # on the read thread, after the reads and checks queued before: one of them may have
        # (re)opened the read connection
        await asyncio.get_running_loop().run_in_executor(self._pool, self._close_reader)
        self._pool.shutdown(wait=False)

    def _close_reader(self) -> None:
        if self._read_db is not None:
            db, self._read_db = self._read_db, None
            db.close()

    def owns(self, region_id: str) -> bool:
        return region_id in self.owned


__all__ = ["ClusterMember", "RegionCallback", "region_map_of"]
