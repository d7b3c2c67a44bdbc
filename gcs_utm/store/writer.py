"""One writer thread owning the write connection, and the asyncio face of the store.

Queue policy (bounded, ``StoreConfig.queue_size``):
- track history is *droppable*: when the queue is full the batch is dropped and counted
  (``StoreWriter.dropped_tracks``) with a log line, because a lost sample of a 10 Hz track is
  harmless and blocking Tracking is not;
- everything else (operations, plans, geofences, threats, recommendations, answers, audit) is
  *kept*: the caller waits up to ``put_timeout_s`` for space and then gets
  :class:`StoreFullError`; nothing is silently lost.

The writer takes one request, then drains up to ``batch_max`` more without waiting, and runs
them in ONE transaction, each in its own savepoint: a failing request rolls back alone and its
future gets the exception; the others commit. Futures resolve only after COMMIT, so awaiting
one means the row is durable. Reads use a separate read-only connection on its own thread.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from gcs_utm.messages import PilotAnswer
from gcs_utm.model import (
    AuditEntry,
    FlightPlan,
    Geofence,
    GeofenceId,
    Operation,
    Recommendation,
    RecommendationState,
    Threat,
    Track,
)
from gcs_utm.store.base import Connection, StoreBase, StoreError
from gcs_utm.store.config import StoreConfig
from gcs_utm.store.location import describe, is_postgres, open_store

_log = logging.getLogger(__name__)

T = TypeVar("T")
_Job = tuple[Callable[[StoreBase], Any], concurrent.futures.Future[Any]]
# how long the writer waits between attempts to reopen a lost PostgreSQL connection
_RECONNECT_S = 1.0


class StoreFullError(StoreError):
    """A must-keep write found the queue full for longer than its timeout."""


class StoreWriter:
    """The single writer thread. Thread-safe to call from anywhere. ``location`` is a SQLite
    file path or a ``postgresql://`` URL (:func:`gcs_utm.store.open_store`)."""

    def __init__(self, location: str | Path, config: StoreConfig | None = None) -> None:
        self.config = config or StoreConfig()
        self.location: str | Path = location if is_postgres(location) else Path(location)
        self.where = describe(location)
        self._queue: queue.Queue[_Job | None] = queue.Queue(maxsize=self.config.queue_size)
        self._ready = concurrent.futures.Future[None]()
        self._closed = False
        self.dropped_tracks = 0
        self.committed_batches = 0
        # The life this writer begins when it opens the store (see Store.begin_life): the
        # service prefixes its ids with it.
        self.epoch = 0
        self._fence: Callable[[Connection, str], None] | None = None
        self._thread = threading.Thread(target=self._run, name="store-writer", daemon=True)
        self._thread.start()
        self._ready.result()  # raises if the file cannot be opened or migrated

    # ---- submission ---------------------------------------------------------------------
    def submit(
        self, fn: Callable[[StoreBase], T], *, droppable: bool = False
    ) -> concurrent.futures.Future[T] | None:
        """Queue ``fn(store)``; returns its future, or None if it was droppable and dropped."""
        if self._closed:
            raise StoreError(f"{self.where}: the store writer is closed")
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()
        job: _Job = (fn, fut)
        if droppable:
            try:
                self._queue.put_nowait(job)
            except queue.Full:
                self.dropped_tracks += 1
                if self.dropped_tracks == 1 or self.dropped_tracks % 1000 == 0:
                    _log.warning(
                        "store queue full: dropped %d track batches so far", self.dropped_tracks
                    )
                return None
            return fut
        try:
            self._queue.put(job, timeout=self.config.put_timeout_s)
        except queue.Full:
            raise StoreFullError(
                f"{self.where}: write queue full for {self.config.put_timeout_s} s"
            ) from None
        return fut

    def _must(self, fn: Callable[[StoreBase], T]) -> concurrent.futures.Future[T]:
        fut = self.submit(fn)
        assert fut is not None
        return fut

    def write_tracks(self, tracks: Sequence[Track]) -> concurrent.futures.Future[None] | None:
        batch = list(tracks)
        return self.submit(lambda s: s.write_tracks(batch), droppable=True)

    def save_operation(self, op: Operation) -> concurrent.futures.Future[None]:
        return self._must(lambda s: s.save_operation(op))

    def save_plan(self, plan: FlightPlan) -> concurrent.futures.Future[None]:
        return self._must(lambda s: s.save_plan(plan))

    def save_geofence(
        self, fence: Geofence, *, active: bool = True
    ) -> concurrent.futures.Future[None]:
        return self._must(lambda s: s.save_geofence(fence, active=active))

    def deactivate_geofence(self, fence_id: GeofenceId | str) -> concurrent.futures.Future[bool]:
        return self._must(lambda s: s.deactivate_geofence(fence_id))

    def save_threat(self, threat: Threat) -> concurrent.futures.Future[None]:
        return self._must(lambda s: s.save_threat(threat))

    def save_recommendation(self, rec: Recommendation) -> concurrent.futures.Future[None]:
        return self._must(lambda s: s.save_recommendation(rec))

    def record_answer(self, answer: PilotAnswer) -> concurrent.futures.Future[None]:
        return self._must(lambda s: s.record_answer(answer))

    def audit(self, entry: AuditEntry) -> concurrent.futures.Future[int]:
        return self._must(lambda s: s.audit(entry))

    def set_fence(
        self, fence: Callable[[Connection, str], None] | None
    ) -> concurrent.futures.Future[None]:
        """Check every write of a region-owned row against ``fence`` (a cluster member's
        lease fence, :attr:`StoreBase.fence`), on this connection and on every reconnection."""
        self._fence = fence

        def install(s: StoreBase) -> None:
            s.fence = fence

        return self._must(install)

    def flush(self, timeout_s: float | None = None) -> None:
        """Wait until everything queued so far is committed."""
        self._must(lambda s: None).result(timeout=timeout_s)

    def close(self, timeout_s: float | None = 30.0) -> None:
        """Commit what is queued, then stop the thread and close the connection."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join(timeout_s)

    # ---- the thread ---------------------------------------------------------------------
    def _open(self) -> StoreBase:
        return open_store(
            self.location,
            synchronous=self.config.synchronous,
            busy_timeout_s=self.config.busy_timeout_s,
        )

    def _reopen(self, lost: StoreBase) -> StoreBase:
        """A new connection in the same life after the database connection was lost (a
        PostgreSQL restart or failover); retried every ``_RECONNECT_S`` until it opens, while
        the bounded queue applies its policy to the writes arriving meanwhile."""
        lost.close()
        while True:
            try:
                store = self._open()
            except StoreError as exc:
                _log.warning("store %s unreachable, retrying: %s", self.where, exc)
                time.sleep(_RECONNECT_S)
                continue
            store._epoch = self.epoch
            store.fence = self._fence
            _log.warning("store %s reconnected", self.where)
            return store

    def _run(self) -> None:
        try:
            store = self._open()
        except BaseException as exc:
            self._ready.set_exception(exc)
            return
        try:
            self.epoch = store.begin_life()
        except BaseException as exc:
            store.close()
            self._ready.set_exception(exc)
            return
        self._ready.set_result(None)
        try:
            stop = False
            while not stop:
                first = self._queue.get()
                if first is None:
                    break
                batch = [first]
                while len(batch) < self.config.batch_max:
                    try:
                        nxt = self._queue.get_nowait()
                    except queue.Empty:
                        break
                    if nxt is None:
                        stop = True
                        break
                    batch.append(nxt)
                self._commit(store, batch)
                if getattr(store, "broken", False):
                    store = self._reopen(store)
        finally:
            store.close()

    def _commit(self, store: StoreBase, batch: list[_Job]) -> None:
        results: list[tuple[concurrent.futures.Future[Any], bool, Any]] = []
        try:
            with store.transaction():
                for fn, fut in batch:
                    try:
                        with store.transaction():  # a savepoint per request
                            results.append((fut, True, fn(store)))
                    except Exception as exc:
                        results.append((fut, False, exc))
        except Exception as exc:  # the COMMIT itself failed: nothing of the batch is stored
            _log.error("store batch of %d failed to commit: %s", len(batch), exc)
            for _fn, fut in batch:
                fut.set_exception(StoreError(f"commit failed: {exc}"))
            return
        self.committed_batches += 1
        for fut, ok, value in results:
            if ok:
                fut.set_result(value)
            else:
                fut.set_exception(value)


class AsyncStore:
    """The store for asyncio code: writes through a :class:`StoreWriter`, reads on a
    read-only connection in its own thread; nothing here blocks the event loop.

    ``write_tracks`` is fire-and-forget (droppable). The other writes return after COMMIT.
    """

    def __init__(self, location: str | Path, config: StoreConfig | None = None) -> None:
        self.writer = StoreWriter(location, config)
        self._reads = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="store-read")
        self._reader: StoreBase | None = None

    @classmethod
    async def open(cls, location: str | Path, config: StoreConfig | None = None) -> AsyncStore:
        """Open (creating/migrating the database) without blocking the loop."""
        return await asyncio.get_running_loop().run_in_executor(None, lambda: cls(location, config))

    async def close(self) -> None:
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, self.writer.close)

        def close_reader() -> None:
            if self._reader is not None:
                self._reader.close()

        await loop.run_in_executor(self._reads, close_reader)
        self._reads.shutdown(wait=True)

    async def __aenter__(self) -> AsyncStore:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def _put(self, fn: Callable[[StoreBase], T]) -> T:
        """Queue a must-keep write without blocking the loop, then await its commit."""
        loop = asyncio.get_running_loop()
        fut = await loop.run_in_executor(None, lambda: self.writer.submit(fn))
        assert fut is not None
        return await asyncio.wrap_future(fut, loop=loop)

    def write_tracks(self, tracks: Sequence[Track]) -> bool:
        """Queue tracks for latest + history; False if dropped because the queue is full."""
        return self.writer.write_tracks(tracks) is not None

    async def save_operation(self, op: Operation) -> None:
        await self._put(lambda s: s.save_operation(op))

    async def save_plan(self, plan: FlightPlan) -> None:
        await self._put(lambda s: s.save_plan(plan))

    async def save_geofence(self, fence: Geofence, *, active: bool = True) -> None:
        await self._put(lambda s: s.save_geofence(fence, active=active))

    async def deactivate_geofence(self, fence_id: GeofenceId | str) -> bool:
        return await self._put(lambda s: s.deactivate_geofence(fence_id))

    async def save_threat(self, threat: Threat) -> None:
        await self._put(lambda s: s.save_threat(threat))

    async def save_recommendation(self, rec: Recommendation) -> None:
        await self._put(lambda s: s.save_recommendation(rec))

    async def record_answer(self, answer: PilotAnswer) -> None:
        await self._put(lambda s: s.record_answer(answer))

    async def audit(self, entry: AuditEntry) -> int:
        return await self._put(lambda s: s.audit(entry))

    async def flush(self) -> None:
        await self._put(lambda s: None)

    # ---- reads --------------------------------------------------------------------------
    async def read(self, fn: Callable[[StoreBase], T]) -> T:
        """Run ``fn`` on the read-only connection in the reader thread."""

        def run() -> T:
            if self._reader is None:
                self._reader = open_store(self.writer.location, readonly=True)
            return fn(self._reader)

        return await asyncio.get_running_loop().run_in_executor(self._reads, run)

    async def load_operations(self) -> list[Operation]:
        return await self.read(lambda s: s.load_operations())

    async def load_geofences(self, *, active_only: bool = True) -> list[Geofence]:
        return await self.read(lambda s: s.load_geofences(active_only=active_only))

    async def load_recommendations(
        self, *, state: RecommendationState | None = None
    ) -> list[Recommendation]:
        return await self.read(lambda s: s.load_recommendations(state=state))

    async def load_audit(self, since_t_s: float = float("-inf")) -> list[AuditEntry]:
        return await self.read(lambda s: s.load_audit(since_t_s))
