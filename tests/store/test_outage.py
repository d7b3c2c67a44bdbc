"""Store writes across a PostgreSQL outage (the real private server of the tests, killed with
SIGKILL and started again): a batch lost with the connection is kept and retried in order
until it commits, a batch that did commit before the connection broke is not applied twice,
and what is held when the writer stops goes to the local journal the next start replays."""

from __future__ import annotations

import contextlib
import logging
import shutil
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import AuditEntry, RecommendationId
from gcs_utm.store import StoreBase, StoreConfig, StoreError, StoreWriter, open_store
from gcs_utm.store import journal as store_journal
from tests.store import pgserver


@pytest.fixture(scope="module")
def own_server() -> Iterator[pgserver.PgServer]:
    """A private server of this module's own (its tests kill it)."""
    srv, why = pgserver.start()
    if srv is None:
        pytest.skip(f"no PostgreSQL server could be started here: {why}")
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture
def server(own_server: pgserver.PgServer) -> pgserver.PgServer:
    """The module's server, running (a test that failed may have left it killed)."""
    if own_server.proc.poll() is not None:
        _start(own_server)
    return own_server


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, ValueError, IndexError):
            if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(stat.parent.name))
    return out


def _kill(server: pgserver.PgServer) -> None:
    """SIGKILL the postmaster, then wait until its backends have ended too ("terminating
    connection due to unexpected postmaster exit"): from then on nothing can commit."""
    backends = _children(server.proc.pid)
    server.proc.send_signal(signal.SIGKILL)
    server.proc.wait(10)
    deadline = time.monotonic() + 10
    while any(Path(f"/proc/{pid}").exists() for pid in backends):
        assert time.monotonic() < deadline, "postgres backends outlived the postmaster"
        time.sleep(0.02)


def _start(server: pgserver.PgServer) -> None:
    """Start the killed server again on its data (orphaned backends may hold its shared
    memory for a moment: retried)."""
    for _ in range(50):
        with contextlib.suppress(RuntimeError):
            server.restart()
            return
        time.sleep(0.2)
    raise RuntimeError(f"postgres did not come back: {server.log_tail()}")


def _answer(i: int) -> PilotAnswer:
    return PilotAnswer(
        recommendation_id=RecommendationId(f"R{i}"),
        version=1,
        decision=PilotDecision.ACCEPT,
        t_s=float(i),
    )


def _entry(i: int) -> AuditEntry:
    return AuditEntry(t_s=float(i), actor="pilot", action="answer_accept", subject=f"R{i}")


def _rows(url: str) -> tuple[list[str], list[str]]:
    with open_store(url) as s:
        answers = [a.recommendation_id for a in s.load_answers()]
        audit = [e.subject for e in s.load_audit()]
    return answers, audit


def test_answers_written_while_postgres_is_down_commit_once_when_it_is_back(
    server: pgserver.PgServer, caplog: pytest.LogCaptureFixture
) -> None:
    url = server.create_database()
    writer = StoreWriter(url, StoreConfig(batch_max=4))
    events: list[str] = []
    writer.on_event = events.append
    try:
        futs: list[Any] = []
        for i in range(3):  # committed before the outage
            futs += [writer.record_answer(_answer(i)), writer.audit(_entry(i))]
        writer.flush(10)
        _kill(server)
        for i in range(3, 12):  # in flight and queued behind while the database is down
            futs += [writer.record_answer(_answer(i)), writer.audit(_entry(i))]
        with caplog.at_level(logging.WARNING, "gcs_utm.store.writer"):
            deadline = time.monotonic() + 10
            while writer.outage() is None and time.monotonic() < deadline:
                time.sleep(0.02)
            assert writer.outage() is not None and "unreachable" in str(writer.outage())
            assert not futs[-1].done()  # held, not failed
            _start(server)
            for f in futs:
                f.result(30)  # every write commits: none raised
        assert writer.outage() is None
        assert any("lost" in e for e in events) and any("back after" in e for e in events)
    finally:
        writer.close()
    answers, audit = _rows(url)
    assert answers == [f"R{i}" for i in range(12)]
    assert audit == [f"R{i}" for i in range(12)]


class _CommitThenCut:
    """A connection whose first COMMIT after ``armed`` goes through and then the connection
    is cut before the writer hears back: the batch is stored, the writer cannot know it."""

    def __init__(self, conn: Any) -> None:
        self._conn = conn
        self.armed = False

    def execute(self, sql: str, params: Any = (), /) -> Any:
        cur = self._conn.execute(sql, params)
        if self.armed and sql == "COMMIT":
            self.armed = False
            self._conn.raw.close()
            raise StoreError("server closed the connection unexpectedly")
        return cur

    def __getattr__(self, name: str) -> Any:
        return getattr(self._conn, name)


class _CuttingWriter(StoreWriter):
    cut: _CommitThenCut | None = None

    def _open(self) -> StoreBase:
        store = super()._open()
        if self.cut is None:
            self.cut = _CommitThenCut(store._conn)
            store._conn = self.cut
        return store


def test_a_batch_that_committed_before_the_cut_is_not_applied_twice(
    pg_url: str,
) -> None:
    writer = _CuttingWriter(pg_url, StoreConfig(batch_max=8))
    try:
        writer.flush(10)
        assert writer.cut is not None
        writer.cut.armed = True
        futs = [writer.record_answer(_answer(1)), writer.audit(_entry(1))]
        assert futs[0].result(30) is None and futs[1].result(30) >= 1
        writer.record_answer(_answer(2)).result(30)
        assert writer.cut.armed is False  # the cut happened
    finally:
        writer.close()
    answers, audit = _rows(pg_url)
    assert answers == ["R1", "R2"] and audit == ["R1"]


def test_writes_held_at_stop_go_to_the_journal_and_the_next_start_replays_them(
    server: pgserver.PgServer, tmp_path: Path
) -> None:
    url = server.create_database()
    pending = tmp_path / "store.journal"
    writer = StoreWriter(url, StoreConfig(batch_max=2), journal=pending)
    writer.record_answer(_answer(0)).result(10)
    _kill(server)
    futs = [writer.record_answer(_answer(i)) for i in range(1, 6)] + [writer.audit(_entry(5))]
    deadline = time.monotonic() + 10
    while writer.outage() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    writer.close()
    for f in futs:  # not committed, and they say so
        with pytest.raises(StoreError, match="unreachable"):
            f.result(1)
    kept = store_journal.read(pending)
    assert [op[0] for b in kept for op in b.ops] == ["record_answer"] * 5 + ["audit"]
    copy = tmp_path / "copy.journal"
    shutil.copy(pending, copy)
    _start(server)
    StoreWriter(url, journal=pending).close()  # the next start replays it
    assert not pending.exists()
    shutil.copy(copy, pending)  # a replay that runs again (a crash before the file went)
    StoreWriter(url, journal=pending).close()
    answers, audit = _rows(url)
    assert answers == [f"R{i}" for i in range(6)] and audit == ["R5"]


def test_a_corrupt_journal_is_one_error_naming_the_file(pg_url: str, tmp_path: Path) -> None:
    pending = tmp_path / "store.journal"
    pending.write_text('{"store": "x", "epoch": 1, "batch": 1, "ops": [["drop_table", []]]}\n')
    with pytest.raises(StoreError, match=r"store\.journal:1: not a store journal entry"):
        StoreWriter(pg_url, journal=pending)
    pending.write_text(
        '{"store": "postgresql://elsewhere/db", "epoch": 1, "batch": 1, "ops": []}\n'
    )
    with pytest.raises(StoreError, match="journal of the store postgresql://elsewhere/db, not of"):
        StoreWriter(pg_url, journal=pending)
    pending.write_text('{"epoch": 1, "batch": 1, "op')  # torn last line: ignored
    StoreWriter(pg_url, journal=pending).close()
    assert not pending.exists()


def test_postgres_killed_and_restarted_while_answers_stream_in_loses_none(
    server: pgserver.PgServer,
) -> None:
    """Answers and their audit entries keep arriving (every 2 ms) while the postmaster is
    killed and started again: every one is stored exactly once, in order."""
    url = server.create_database()
    writer = StoreWriter(url, StoreConfig(batch_max=8, put_timeout_s=30.0))
    futs: list[Any] = []

    def stream() -> None:
        for i in range(150):
            futs.extend([writer.record_answer(_answer(i)), writer.audit(_entry(i))])
            time.sleep(0.002)

    feeder = threading.Thread(target=stream)
    try:
        feeder.start()
        while len(futs) < 40:
            time.sleep(0.005)
        _kill(server)
        _start(server)
        feeder.join(60)
        for f in futs:
            f.result(30)
    finally:
        writer.close()
    answers, audit = _rows(url)
    assert answers == [f"R{i}" for i in range(150)]
    assert audit == [f"R{i}" for i in range(150)]
