"""A standby survives a database that dropped its connections: every member connection is
checked each lease round and bounded by a statement timeout, and a takeover whose region
cannot be loaded hands the region back and takes it again on a later round, instead of
ending the process."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from gcs_utm.cluster import lease
from gcs_utm.cluster import node as node_module
from gcs_utm.cluster.exchange import RemoteTrack
from gcs_utm.model import OperationId
from gcs_utm.store import FencedError, StoreBase, StoreConfig, StoreError, open_store
from tests.cluster.harness import Member, config, file_airspace, frame, member
from tests.store.conftest import raw_execute


def _kill_backends(url: str) -> None:
    """Terminate every other session of the test database (what a PostgreSQL restart does
    to its clients: 'terminating connection due to administrator command')."""
    raw_execute(
        url,
        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
        "WHERE datname = current_database() AND pid <> pg_backend_pid()",
    )


def _expire(url: str, region_id: str) -> None:
    """The owner died: its lease runs out (on the database clock)."""
    raw_execute(url, f"UPDATE region_leases SET expires_unix_s = 0 WHERE region_id = '{region_id}'")


async def _step_until(m: Member, wanted: str, rounds: int = 5) -> list[str]:
    seen: list[str] = []
    for _ in range(rounds):
        seen += await m.step()
        if wanted in seen:
            return seen
    raise AssertionError(f"{wanted!r} not within {rounds} rounds: {seen}")


@pytest.mark.timeout(60)
async def test_a_standby_takes_over_after_its_connections_were_cut(pg_url: str) -> None:
    file_airspace(pg_url)
    a = await member(pg_url, config("A", "c0r0", standby=False))
    b = await member(pg_url, config("B", "c1r0", standby=True))
    try:
        assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
        # B holds a region but never read since: its read connection is idle
        _kill_backends(pg_url)
        _expire(pg_url, "c0r0")  # A is gone too
        seen = await _step_until(b, "gained c0r0")
        assert "lost c1r0" not in seen and b.failed == []
        assert OperationId("UAS1") in b.airspace.ops  # the region was loaded
        with open_store(pg_url) as s:
            held = {r: h for r, h in lease.owners(s).items()}
        assert held == {"c0r0": b.node.member.holder, "c1r0": b.node.member.holder}
    finally:
        await a.close()
        await b.close()


@pytest.mark.timeout(60)
async def test_a_takeover_that_cannot_load_hands_the_region_back_and_retries(
    pg_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    file_airspace(pg_url)
    b = await member(pg_url, config("B", "c1r0", standby=True))
    real_load = node_module.load_region
    calls: list[str] = []

    def failing_once(*args: object, **kwargs: object) -> object:
        calls.append(str(args[1]))
        if len(calls) == 1:
            raise StoreError("terminating connection due to administrator command")
        return real_load(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(node_module, "load_region", failing_once)
    try:
        # B first takes its own region: the load fails, the region is handed back
        assert await b.step() == ["gained c1r0"]
        assert b.failed == [] and "c1r0" not in b.node.resumed
        assert any("c1r0 not taken" in e and "handed back" in e for e in b.usm.events)
        # the next round releases it, finds it free, and takes it again: loaded this time
        assert await b.step() == ["gained c1r0"]
        assert calls == ["c1r0", "c1r0"] and "c1r0" in b.node.resumed
        assert OperationId("UAS2") in b.airspace.ops and b.failed == []
    finally:
        await b.close()


def test_member_connections_carry_a_statement_timeout_and_keepalive(pg_url: str) -> None:
    from gcs_utm.store.postgres import PgStore

    with open_store(pg_url, statement_timeout_s=0.25) as s:
        assert isinstance(s, PgStore)
        assert s._rows("SHOW statement_timeout") == [("250ms",)]
        with pytest.raises(StoreError, match="statement timeout"):
            s._rows("SELECT pg_sleep(2)")
        assert s._conn.raw.info.get_parameters()["keepalives"] == "1"


async def test_a_connection_check_queued_before_close_leaves_no_connection_open(
    pg_url: str,
) -> None:
    """A lease round queues a check of the read connection; a stop right behind it must not
    leave the connection that check opens behind, unclosed (the ResourceWarning then fails
    whatever test the garbage collector happens to run in)."""
    file_airspace(pg_url)
    a = await member(pg_url, config("A", "c0r0", standby=False))
    cm = a.node.member

    def forget_reader() -> None:  # as a member that has not read yet
        if cm._read_db is not None:
            cm._read_db.close()
            cm._read_db = None

    await asyncio.to_thread(forget_reader)
    busy = threading.Event()
    cm._pool.submit(busy.wait)  # the read thread is busy with an earlier read ...
    cm._check_reader()  # ... a check of the connection queues behind it ...
    stopping = asyncio.create_task(a.close())  # ... and the member stops
    await asyncio.sleep(0.2)
    busy.set()
    await stopping
    await asyncio.to_thread(cm._pool.shutdown, wait=True)
    assert cm._read_db is None


@pytest.mark.timeout(60)
async def test_a_writer_stuck_in_a_fenced_write_delays_a_takeover_at_most_its_bound(
    pg_url: str,
) -> None:
    """A's writer stalls inside a batch, after the fence share-locked its region's lease row
    (a SIGSTOP, a swapped-out process): B's takeover waits on that lock. The writer's
    session is bounded (serve --cluster: ``lease_s``), so the server ends it and B takes the
    region; A's writer then retries the batch on a new connection and is fenced out."""
    lease_s = 1.0
    ops = file_airspace(pg_url)
    a = await member(
        pg_url,
        config("A", "c0r0", standby=False, lease_s=lease_s),
        store_config=StoreConfig(statement_timeout_s=lease_s),
    )
    b = await member(pg_url, config("B", "c1r0", standby=True, lease_s=lease_s))
    inside, release = threading.Event(), threading.Event()

    def stuck_write(s: StoreBase) -> None:
        s.save_operation(ops[0])  # UAS1, region c0r0: fenced, its lease row share-locked
        if not inside.is_set():
            inside.set()
            release.wait(30.0)  # stalled inside the transaction

    try:
        assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
        a.airspace.ops[ops[0].id] = ops[0]  # the fence maps UAS1 to c0r0
        stalled = time.monotonic()
        done = a.writer.submit(stuck_write)
        assert done is not None and await asyncio.to_thread(inside.wait, 5.0)
        # A renews no more (stalled); B takes c0r0 once A's lease expired and the writer's
        # session was ended: lease_s + the writer's bound, plus a round
        await b.step_until("gained c0r0", timeout_s=3 * lease_s + 2.0)
        assert time.monotonic() - stalled <= 2 * lease_s + 1.0
        release.set()
        with pytest.raises(FencedError):  # the retried batch is refused by the fence
            await asyncio.wrap_future(done)
        for _ in range(50):
            if a.failed:
                break
            await asyncio.sleep(0.1)
        assert a.failed and "fenced" in a.failed[0]
        with open_store(pg_url) as s:
            assert lease.owners(s)["c0r0"] == b.node.member.holder
    finally:
        release.set()
        await a.close()
        await b.close()


@pytest.mark.timeout(60)
async def test_traffic_of_another_instance_after_a_database_restart_is_survived(
    pg_url: str,
) -> None:
    """Another instance's track arrives in B's halo just after PostgreSQL cut B's read
    connection: loading that operation fails, the message is dropped (the next one loads
    it), and the exchange, and with it the process, goes on."""
    file_airspace(pg_url)
    b = await member(pg_url, config("B", "c1r0", standby=False))
    try:
        assert await b.step() == ["gained c1r0"]
        await b.node.member.read(lambda s: s.now_unix_s())  # the read connection is open
        cm = b.node.member
        border_m = cm.map.west_m + cm.map.cell_m  # c0r0's east edge: inside B's halo
        lat, lon = frame().point_to_wgs84(border_m - 50.0, -4000.0)
        track = RemoteTrack(
            region_id="c0r0",
            operation_id=OperationId("UAS1"),
            t_s=0.0,
            lat_deg=lat,
            lon_deg=lon,
            alt_amsl_m=700.0,
            vel_enu_mps=(0.0, 0.0, 0.0),
            position_sigma_m=1.0,
        )
        _kill_backends(pg_url)  # a restart: B's idle read connection is cut
        await b.node.on_remote_tracks([track])  # raised StoreError before
        assert OperationId("UAS1") not in b.node.policy.foreign
        await b.node.on_remote_tracks([track])  # a new connection: loaded and watched
        assert OperationId("UAS1") in b.node.policy.foreign
        assert b.node.foreign_measurements == 1 and b.failed == []
    finally:
        await b.close()
