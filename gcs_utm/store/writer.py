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
import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

from gcs_utm.messages import PilotAnswer
from gcs_utm.model import (
    AuditEntry,
    FlightPlan,
    Geofence,
    GeofenceId,
    Operation,
    Recommendation,
    RecommendationState,
    RemoteIdentity,
    Threat,
    Track,
    TrackId,
)
from gcs_utm.store import journal
from gcs_utm.store.base import Connection, StoreBase, StoreError
from gcs_utm.store.config import StoreConfig
from gcs_utm.store.journal import JournalBatch, Op
from gcs_utm.store.location import describe, is_postgres, open_store

_log = logging.getLogger(__name__)

T = TypeVar("T")
# how long the writer waits between attempts to reopen a lost PostgreSQL connection
_RECONNECT_S = 1.0
# how often a continuing outage is logged again
_OUTAGE_LOG_S = 30.0


class StoreFullError(StoreError):
    """A must-keep write found the queue full for longer than its timeout."""


class _Job(NamedTuple):
    fn: Callable[[StoreBase], Any]
    fut: concurrent.futures.Future[Any]
    op: Op | None  # the write as data, for the journal (None: track history, flush, fence)


_Result = tuple[concurrent.futures.Future[Any], bool, Any]


class StoreWriter:
    """The single writer thread. Thread-safe to call from anywhere. ``location`` is a SQLite
    file path or a ``postgresql://`` URL (:func:`gcs_utm.store.open_store`). ``journal``: the
    local file where the writes still held when the writer stops with the database
    unreachable are kept, and which this writer replays when it starts (see
    :mod:`gcs_utm.store.journal`); None: such writes fail (logged)."""

    def __init__(
        self,
        location: str | Path,
        config: StoreConfig | None = None,
        *,
        journal: Path | None = None,
    ) -> None:
        self.config = config or StoreConfig()
        self.location: str | Path = location if is_postgres(location) else Path(location)
        self.where = describe(location)
        self.journal = journal
        self._queue: queue.Queue[_Job | None] = queue.Queue(maxsize=self.config.queue_size)
        self._ready = concurrent.futures.Future[None]()
        self._closed = False
        self._closing = threading.Event()
        self.dropped_tracks = 0
        self.committed_batches = 0
        # The life this writer begins when it opens the store (see Store.begin_life): the
        # service prefixes its ids with it.
        self.epoch = 0
        self._fence: Callable[[Connection, str], None] | None = None
        # Called (from the writer thread) with each line the operator must see: an outage,
        # its end, a spill to the journal, a replay (the service shows them as events).
        self.on_event: Callable[[str], None] | None = None
        # wall-clock start of the current database outage (None: reachable)
        self.outage_since_unix_s: float | None = None
        self._outage_logged_s = 0.0
        self._thread = threading.Thread(target=self._run, name="store-writer", daemon=True)
        self._thread.start()
        self._ready.result()  # raises if the file cannot be opened or migrated

    # ---- submission ---------------------------------------------------------------------
    def submit(
        self, fn: Callable[[StoreBase], T], *, droppable: bool = False, op: Op | None = None
    ) -> concurrent.futures.Future[T] | None:
        """Queue ``fn(store)``; returns its future, or None if it was droppable and dropped.
        ``op``: the same write as data (:mod:`gcs_utm.store.journal`), so that it can be
        journalled when the database is unreachable at stop."""
        if self._closed:
            raise StoreError(f"{self.where}: the store writer is closed")
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()
        job = _Job(fn, fut, op)
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

    def _must(self, name: str, *args: Any) -> concurrent.futures.Future[Any]:
        """Queue the must-keep write ``store.<name>(*args)`` (journalled if need be)."""
        op: Op = (name, args)
        fut = self.submit(lambda s: journal.apply(s, op), op=op)
        assert fut is not None
        return fut

    def write_tracks(self, tracks: Sequence[Track]) -> concurrent.futures.Future[None] | None:
        batch = list(tracks)
        return self.submit(lambda s: s.write_tracks(batch), droppable=True)

    def write_remote_ids(
        self, rows: Sequence[tuple[TrackId, RemoteIdentity]]
    ) -> concurrent.futures.Future[None] | None:
        """Latest-wins state like the tracks: dropped when the queue is full."""
        batch = list(rows)
        return self.submit(lambda s: s.save_remote_ids(batch), droppable=True)

    def save_operation(self, op: Operation) -> concurrent.futures.Future[None]:
        return self._must("save_operation", op)

    def save_plan(self, plan: FlightPlan) -> concurrent.futures.Future[None]:
        return self._must("save_plan", plan)

    def save_geofence(
        self, fence: Geofence, *, active: bool = True
    ) -> concurrent.futures.Future[None]:
        return self._must("save_geofence", fence, active)

    def deactivate_geofence(self, fence_id: GeofenceId | str) -> concurrent.futures.Future[bool]:
        return self._must("deactivate_geofence", str(fence_id))

    def save_threat(self, threat: Threat) -> concurrent.futures.Future[None]:
        return self._must("save_threat", threat)

    def save_recommendation(self, rec: Recommendation) -> concurrent.futures.Future[None]:
        return self._must("save_recommendation", rec)

    def record_answer(self, answer: PilotAnswer) -> concurrent.futures.Future[None]:
        return self._must("record_answer", answer)

    def audit(self, entry: AuditEntry) -> concurrent.futures.Future[int]:
        return self._must("audit", entry)

    def set_fence(
        self, fence: Callable[[Connection, str], None] | None
    ) -> concurrent.futures.Future[None]:
        """Check every write of a region-owned row against ``fence`` (a cluster member's
        lease fence, :attr:`StoreBase.fence`), on this connection and on every reconnection."""
        self._fence = fence

        def install(s: StoreBase) -> None:
            s.fence = fence

        fut = self.submit(install)
        assert fut is not None
        return fut

    def flush(self, timeout_s: float | None = None) -> None:
        """Wait until everything queued so far is committed."""
        fut = self.submit(lambda s: None)
        assert fut is not None
        fut.result(timeout=timeout_s)

    def close(self, timeout_s: float | None = 30.0) -> None:
        """Commit what is queued, then stop the thread and close the connection. While the
        database is unreachable, what is held goes to the journal instead."""
        if self._closed:
            return
        self._closed = True
        self._closing.set()
        self._queue.put(None)
        self._thread.join(timeout_s)

    def outage(self) -> str | None:
        """A line for the operator while the database is unreachable, else None."""
        since = self.outage_since_unix_s
        if since is None:
            return None
        return (
            f"store {self.where} unreachable for {time.time() - since:.0f} s: "
            f"{self._queue.qsize()} writes queued, retrying"
        )

    # ---- the thread ---------------------------------------------------------------------
    def _open(self) -> StoreBase:
        return open_store(
            self.location,
            synchronous=self.config.synchronous,
            busy_timeout_s=self.config.busy_timeout_s,
            statement_timeout_s=self.config.statement_timeout_s,
        )

    def _tell(self, level: int, text: str) -> None:
        _log.log(level, "%s", text)
        if self.on_event is not None:
            try:
                self.on_event(text)
            except Exception:  # the operator's display must not stop the writer
                _log.exception("store event hook failed")

    def _reopen(self, lost: StoreBase) -> StoreBase | None:
        """A new connection in the same life after the database connection was lost (a
        PostgreSQL restart or failover); retried every ``_RECONNECT_S`` until it opens, while
        the bounded queue applies its policy to the writes arriving meanwhile. None when the
        writer is asked to stop before it opens (one last attempt is made then)."""
        lost.close()
        while True:
            try:
                store = self._open()
            except StoreError as exc:
                now = time.time()
                if now - self._outage_logged_s >= _OUTAGE_LOG_S:
                    self._outage_logged_s = now
                    _log.warning("%s (%s)", self.outage(), exc)
                if self._closing.is_set():
                    return None
                self._closing.wait(_RECONNECT_S)
                continue
            store._epoch = self.epoch
            store.fence = self._fence
            return store

    def _run(self) -> None:
        try:
            store = self._open()
        except BaseException as exc:
            self._ready.set_exception(exc)
            return
        try:
            self.epoch = store.begin_life()
            if self.journal is not None:
                replay(store, self.journal, self._tell)
                store._epoch = self.epoch
        except BaseException as exc:
            store.close()
            self._ready.set_exception(exc)
            return
        self._ready.set_result(None)
        current: StoreBase | None = store
        try:
            current = self._loop(store)
        finally:
            if current is not None:
                current.close()

    def _loop(self, store: StoreBase) -> StoreBase | None:
        """Take batches off the queue and commit them, numbered 1, 2, ... in order, until
        stopped; returns the open store (None when it stopped while unreachable)."""
        seq = 0
        while True:
            first = self._queue.get()
            if first is None:
                return store
            batch = [first]
            stop = False
            while len(batch) < self.config.batch_max:
                try:
                    nxt = self._queue.get_nowait()
                except queue.Empty:
                    break
                if nxt is None:
                    stop = True
                    break
                batch.append(nxt)
            seq += 1
            written = self._write(store, batch, seq)
            if written is None:
                return None
            store = written
            if stop:
                return store

    def _write(self, store: StoreBase, batch: list[_Job], seq: int) -> StoreBase | None:
        """Commit ``batch`` as this life's batch ``seq``. While the connection is lost the
        batch is kept and retried, in order (nothing behind it is written first), on each
        new connection; a retry first asks whether the batch committed before the
        connection broke (``lives.committed_batch``), so it is never applied twice. Returns
        the store to go on with, or None when the writer stopped before the database came
        back (the batch and the rest of the queue then went to the journal)."""
        ran: list[_Result] | None = None
        while True:
            error: Exception | None
            try:
                if ran is not None and store.committed_batch(self.epoch) >= seq:
                    error = None  # it did commit: the results of that attempt stand
                else:
                    ran, error = self._attempt(store, batch, seq)
            except StoreError as exc:  # asking on a connection lost again
                error = exc
            if error is None:
                assert ran is not None
                self._committed(ran)
                return store
            if not getattr(store, "broken", False):
                # the database refused the COMMIT on a live connection: a retry cannot help
                _log.error("store batch of %d failed to commit: %s", len(batch), error)
                for job in batch:
                    job.fut.set_exception(StoreError(f"commit failed: {error}"))
                return store
            if self.outage_since_unix_s is None:
                self.outage_since_unix_s = self._outage_logged_s = time.time()
                self._tell(
                    logging.WARNING,
                    f"store {self.where} lost ({error}): holding a batch of {len(batch)} "
                    f"writes, retrying every {_RECONNECT_S:g} s",
                )
            reopened = self._reopen(store)
            if reopened is None:
                self._spill(batch, seq)
                return None
            store = reopened

    def _attempt(
        self, store: StoreBase, batch: list[_Job], seq: int
    ) -> tuple[list[_Result], Exception | None]:
        """Run ``batch`` in one transaction, each request in its own savepoint, marking it
        as batch ``seq``; the results and None if it committed, else what failed."""
        results: list[_Result] = []
        try:
            with store.transaction() as c:
                for job in batch:
                    try:
                        with store.transaction():  # a savepoint per request
                            results.append((job.fut, True, job.fn(store)))
                    except Exception as exc:
                        results.append((job.fut, False, exc))
                store.mark_batch(c, self.epoch, seq)
        except Exception as exc:  # the COMMIT itself failed: nothing of the batch is stored
            return results, exc
        return results, None

    def _committed(self, results: list[_Result]) -> None:
        self.committed_batches += 1
        if self.outage_since_unix_s is not None:
            down_s = time.time() - self.outage_since_unix_s
            self.outage_since_unix_s = None
            self._tell(
                logging.WARNING,
                f"store {self.where} back after {down_s:.0f} s: the held writes committed",
            )
        for fut, ok, value in results:
            if ok:
                fut.set_result(value)
            else:
                fut.set_exception(value)

    def _spill(self, batch: list[_Job], seq: int) -> None:
        """The writer stops with the database unreachable: ``batch`` (this life's batch
        ``seq``) and everything still queued go to the journal, in order, one journal batch
        each as they would have been committed; their futures fail (nothing is committed)."""
        rest: list[_Job] = []
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                break
            if item is not None:  # None: close()'s stop mark
                rest.append(item)
        jobs = batch + rest
        kept = [job.op for job in batch if job.op is not None]
        later = [job.op for job in rest if job.op is not None]
        batches = [JournalBatch(self.where, self.epoch, seq, tuple(kept))] if kept else []
        if later:
            batches.append(JournalBatch(self.where, self.epoch, seq + 1, tuple(later)))
        n_ops = len(kept) + len(later)
        where = "nowhere (no journal)"
        if self.journal is not None and batches:
            try:
                journal.append(self.journal, batches)
                where = str(self.journal)
            except StoreError as exc:
                where = f"nowhere ({exc})"
        level = logging.WARNING if where == str(self.journal) else logging.ERROR
        self._tell(
            level,
            f"store {self.where} unreachable at stop: {n_ops} writes kept in {where} for the "
            f"next start; {len(jobs) - n_ops} track batches and flushes not kept",
        )
        for job in jobs:
            job.fut.set_exception(StoreError(f"{self.where} unreachable: not committed"))


def replay(store: StoreBase, path: Path, tell: Callable[[int, str], None]) -> None:
    """Apply the batches of the journal at ``path`` on ``store`` in order, each in one
    transaction, as the life that made it, skipping those that committed before; then remove
    the file. A write the database refuses is logged and skipped (as it would have been
    then); a lost connection raises and keeps the file for the next start."""
    batches = journal.read(path)
    for b in batches:
        if b.store != store.where:
            raise StoreError(
                f"{path}: journal of the store {b.store}, not of {store.where}: start with "
                "that store to replay it, or move the file away"
            )
    own = store.epoch
    replayed = skipped = 0
    try:
        for b in batches:
            if store.committed_batch(b.epoch) >= b.batch:
                skipped += 1
                continue
            store._epoch = b.epoch  # its threat and recommendation rows stay that life's
            with store.transaction() as c:
                for op in b.ops:
                    try:
                        with store.transaction():
                            journal.apply(store, op)
                    except StoreError as exc:
                        _log.error("journalled %s of life %d refused: %s", op[0], b.epoch, exc)
                store.mark_batch(c, b.epoch, b.batch)
            replayed += 1
    finally:
        store._epoch = own
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    if batches:
        tell(
            logging.WARNING,
            f"store journal {path}: replayed {replayed} batches "
            f"({sum(len(b.ops) for b in batches)} writes), {skipped} had committed already",
        )


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

    async def _put(self, submit: Callable[[], concurrent.futures.Future[T] | None]) -> T:
        """Queue a must-keep write without blocking the loop, then await its commit."""
        loop = asyncio.get_running_loop()
        fut = await loop.run_in_executor(None, submit)
        assert fut is not None
        return await asyncio.wrap_future(fut, loop=loop)

    def write_tracks(self, tracks: Sequence[Track]) -> bool:
        """Queue tracks for latest + history; False if dropped because the queue is full."""
        return self.writer.write_tracks(tracks) is not None

    async def save_operation(self, op: Operation) -> None:
        await self._put(lambda: self.writer.save_operation(op))

    async def save_plan(self, plan: FlightPlan) -> None:
        await self._put(lambda: self.writer.save_plan(plan))

    async def save_geofence(self, fence: Geofence, *, active: bool = True) -> None:
        await self._put(lambda: self.writer.save_geofence(fence, active=active))

    async def deactivate_geofence(self, fence_id: GeofenceId | str) -> bool:
        return await self._put(lambda: self.writer.deactivate_geofence(fence_id))

    async def save_threat(self, threat: Threat) -> None:
        await self._put(lambda: self.writer.save_threat(threat))

    async def save_recommendation(self, rec: Recommendation) -> None:
        await self._put(lambda: self.writer.save_recommendation(rec))

    async def record_answer(self, answer: PilotAnswer) -> None:
        await self._put(lambda: self.writer.record_answer(answer))

    async def audit(self, entry: AuditEntry) -> int:
        return await self._put(lambda: self.writer.audit(entry))

    async def flush(self) -> None:
        await self._put(lambda: self.writer.submit(lambda s: None))

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
