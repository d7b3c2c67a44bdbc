"""The cluster member task: holds this instance's regions and takes over orphaned ones.

Every ``renew_s`` (its own connection on its own thread, never behind the store writer's
queue of track batches, so a busy writer cannot cost a lease):
1. renew each region held; one that cannot be renewed is *lost* (``on_lost``): an instance
   that cannot reach the database for ``lease_s`` stops deciding for its regions, because a
   standby may hold them by then (self-fencing on this instance's monotonic clock, measured
   from the last renewal the database confirmed);
2. claim the configured ``region`` (the preferred owner claims it at once);
3. as a standby, take over a region whose lease has expired (its owner died or was cut
   off), and one never claimed once it has been seen free for ``lease_s`` (which gives its
   configured owner the head start at cluster start).
A region gained calls ``on_gained`` (the instance then loads that region's operations,
geofences and pending recommendations from the store, :mod:`gcs_utm.cluster.resume`). Stopping
releases every lease, so a clean shutdown hands the regions over at once.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import logging
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
        # the halo (what a region's owner watches beyond its border) belongs to the region
        # exchange, which is not built yet (docs/scale-out.md): none until then
        halo_m=0.0,
    )


class ClusterMember:
    """One instance's regions. ``holder`` names this instance life in the lease rows."""

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
        self._renewed_mono: dict[str, float] = {}
        self._free_since_mono: dict[str, float] = {}
        self._db: StoreBase | None = None
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="cluster-lease")
        self.gained_at_mono: dict[str, float] = {}
        self._closed = False

    # ---- database calls, on the member's own thread --------------------------------------
    def _store(self) -> StoreBase:
        if self._db is None or getattr(self._db, "broken", False):
            if self._db is not None:
                self._db.close()
            self._db = open_store(self._location)
        return self._db

    async def _call(self, fn: Callable[[StoreBase], object]) -> object:
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, lambda: fn(self._store()))

    async def read(self, fn: Callable[[StoreBase], object]) -> object:
        """Run ``fn`` on the member's connection (off the loop)."""
        return await self._call(fn)

    async def start(self) -> None:
        """Check (or file) the region map; raises RegionError when the store's differs."""
        await self._call(lambda s: leases_.publish_map(s, self.map))

    # ---- one round ------------------------------------------------------------------------
    async def step(self) -> None:
        """Renew, claim, take over: one round (the loop calls it every ``renew_s``)."""
        try:
            snapshot = await self._call(leases_.leases)
            now_db = await self._call(lambda s: s.now_unix_s())
        except StoreError as exc:
            _log.warning("cluster: lease table unreachable: %s", exc)
            await self._fence()
            return
        assert isinstance(snapshot, dict) and isinstance(now_db, float)
        for region_id in list(self.owned):
            await self._try(region_id)
        for region_id in self._candidates(snapshot, now_db):
            await self._try(region_id)

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

    async def _try(self, region_id: str) -> None:
        try:
            got = await self._call(
                lambda s: leases_.acquire(
                    s, region_id, self.holder, self.epoch, self.config.lease_s
                )
            )
        except StoreError as exc:
            _log.warning("cluster: lease of %s not renewed: %s", region_id, exc)
            await self._fence()
            return
        if got is None:
            if region_id in self.owned:
                await self._lose(region_id, "held by another instance")
            return
        assert isinstance(got, Lease)
        self._renewed_mono[region_id] = time.monotonic()
        if region_id not in self.owned:
            self.owned[region_id] = got
            self.gained_at_mono[region_id] = time.monotonic()
            _log.info(
                "cluster: %s holds region %s (generation %d)",
                self.holder,
                region_id,
                got.generation,
            )
            await self._on_gained(region_id, got)
        else:
            self.owned[region_id] = got

    async def _fence(self) -> None:
        """Regions not renewed for ``lease_s`` are given up here: another may hold them."""
        mono = time.monotonic()
        for region_id in list(self.owned):
            if mono - self._renewed_mono.get(region_id, mono) >= self.config.lease_s:
                await self._lose(region_id, "lease not renewed in time")

    async def _lose(self, region_id: str, why: str) -> None:
        self.owned.pop(region_id, None)
        _log.warning("cluster: %s lost region %s: %s", self.holder, region_id, why)
        await self._on_lost(region_id, None)

    # ---- the task -------------------------------------------------------------------------
    async def run(self) -> None:
        """Rounds every ``renew_s`` until cancelled; then every lease is released."""
        try:
            while True:
                started = time.monotonic()
                await self.step()
                await asyncio.sleep(max(0.0, self.config.renew_s - (time.monotonic() - started)))
        finally:
            await asyncio.shield(self.close())

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        held = list(self.owned)
        self.owned.clear()
        for region_id in held:
            try:
                await self._call(functools.partial(_release, region_id, self.holder))
            except StoreError as exc:
                _log.warning("cluster: release of %s failed: %s", region_id, exc)
        if self._db is not None:
            db, self._db = self._db, None
            await asyncio.get_running_loop().run_in_executor(self._pool, db.close)
        self._pool.shutdown(wait=False)

    def owns(self, region_id: str) -> bool:
        return region_id in self.owned


def _release(region_id: str, holder: str, store: StoreBase) -> bool:
    return leases_.release(store, region_id, holder)


__all__ = ["ClusterMember", "RegionCallback", "region_map_of"]
