"""Store: faithful round trips, plan versions, restart survival, crash durability (SIGKILL),
the writer's queue policy and the asyncio face."""

from __future__ import annotations

import asyncio
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import threading
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    Alternative,
    AuditEntry,
    Command,
    CommandKind,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
    LatLon,
    Maneuver,
    OperationId,
    Position,
    PredictedTrajectories,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
    Track,
    TrackId,
)
from gcs_utm.scenario import load_scenario
from gcs_utm.store import (
    AsyncStore,
    StoreBase,
    StoreConfig,
    StoreError,
    StoreFullError,
    StoreWriter,
    open_store,
)
from gcs_utm.store.codec import encode
from gcs_utm.store.schema import MIGRATIONS, PG_MIGRATIONS
from tests.store.conftest import raw_execute

REPO = Path(__file__).resolve().parents[2]
UC1 = REPO / "config/scenarios/use_case_1.toml"


def _track(i: int, t_s: float, track_id: str = "UAS1") -> Track:
    return Track(
        id=TrackId(track_id),
        t_s=t_s,
        lat_deg=40.66 + i * 1e-5,
        lon_deg=-3.597,
        alt_amsl_m=715.0 + 0.1 * i,
        east_m=1.5 * i,
        north_m=-0.25 * i,
        vel_enu_mps=(3.3, 0.0, 0.1),
        position_sigma_m=1.2,
        cooperative=True,
        operation_id=OperationId(track_id),
        next_waypoint=2,
    )


def _fence(gid: str = "GF1") -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.POLYGON,
        min_alt_amsl_m=675.0,
        max_alt_amsl_m=900.0,
        vertices=(
            LatLon(lat_deg=40.66, lon_deg=-3.60),
            LatLon(lat_deg=40.661, lon_deg=-3.60),
            LatLon(lat_deg=40.661, lon_deg=-3.59),
        ),
        start_t_s=10.0,
        end_t_s=None,
        kind=GeofenceKind.DYNAMIC,
        reason="wildfire",
    )


def _threat() -> Threat:
    snap = PredictedTrajectories(
        t_s=5.0,
        track_ids=(TrackId("UAS1"), TrackId("UAS2")),
        points=np.arange(2 * 3 * 4, dtype=np.float64).reshape(2, 3, 4) / 7.0,
        sigma_m=np.full((2, 3), 1.5),
    )
    return Threat(
        id=ThreatId("T1"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=(OperationId("UAS1"), OperationId("UAS2")),
        detected_at_s=5.0,
        predicted_event_at_s=169.5,
        closest_approach_m=45.9,
        position=Position(lat_deg=40.66, lon_deg=-3.59, alt_amsl_m=775.0),
        area=_fence("jam"),
        snapshot=snap,
    )


def _rec() -> Recommendation:
    sc = load_scenario(UC1)
    plan = replace(sc.operations[0].plan, version=2, reason="avoid UAS2")
    alt = Alternative(
        operation_id=OperationId("UAS1"),
        maneuver=Maneuver.GO_RIGHT,
        plan=plan,
        cost=0.2,
        risk=0.1,
        detail="right",
    )
    other = replace(alt, maneuver=Maneuver.HOLD, plan=None, cost=0.5)
    return Recommendation(
        id=RecommendationId("R1"),
        version=1,
        threat_id=ThreatId("T1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OperationId("UAS1"),
        created_t_s=6.0,
        deadline_t_s=36.0,
        selected=alt,
        command=Command(kind=CommandKind.HOLD, operation_id=OperationId("UAS1")),
        alternatives=(alt, other),
        new_geofence=_fence("new"),
    )


def _fill(store: StoreBase) -> None:
    sc = load_scenario(UC1)
    for op in sc.operations:
        store.save_operation(op)
    store.save_geofence(_fence())
    store.write_tracks([_track(i, float(i)) for i in range(5)])
    store.save_threat(_threat())
    store.save_recommendation(_rec())
    store.record_answer(
        PilotAnswer(
            recommendation_id=RecommendationId("R1"),
            version=1,
            decision=PilotDecision.ACCEPT,
            t_s=9.0,
            alternative_index=0,
        )
    )
    store.audit(AuditEntry(t_s=9.5, actor="em", action="select", subject="R1", detail={"a": 1}))


def _snapshot(store: StoreBase) -> dict[str, object]:
    threats = store.load_threats()
    return {
        "ops": store.load_operations(),
        "plans": store.load_plans("UAS1"),
        "fences": store.load_geofences(active_only=False),
        "latest": store.latest_tracks(),
        "history": store.track_history("UAS1"),
        "threat_ids": [t.id for t in threats],
        "recs": store.load_recommendations(),
        "answers": store.load_answers(),
        "audit": store.load_audit(),
    }


def test_round_trip_of_every_model_object(db: str | Path) -> None:
    with open_store(db) as store:
        _fill(store)
        sc = load_scenario(UC1)
        assert store.load_operations() == list(sc.operations)
        assert store.load_geofences() == [_fence()]
        assert store.track_history("UAS1") == [_track(i, float(i)) for i in range(5)]
        assert store.latest_tracks() == [_track(4, 4.0)]
        (threat,) = store.load_threats()
        orig = _threat()
        assert threat.snapshot is not None and orig.snapshot is not None
        assert np.array_equal(threat.snapshot.points, orig.snapshot.points)
        # Threat compares by identity (eq=False): compare every field's stored form instead
        assert encode(threat) == encode(orig)
        assert threat.area == orig.area and threat.uas_ids == orig.uas_ids
        (rec,) = store.load_recommendations()
        assert rec == _rec()
        assert store.load_answers("R1")[0].decision is PilotDecision.ACCEPT
        assert store.load_audit() == [
            AuditEntry(t_s=9.5, actor="em", action="select", subject="R1", detail={"a": 1})
        ]


def test_restart_loads_everything_back_equal(db: str | Path) -> None:
    with open_store(db) as store:
        _fill(store)
        before = _snapshot(store)
    with open_store(db) as store:
        assert _snapshot(store) == before
        assert store.integrity_check() == "ok"
        assert store.schema_version == len(MIGRATIONS)
    if isinstance(db, Path):
        conn = sqlite3.connect(db)
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        conn.close()


def test_plan_versions_and_latest(db: str | Path) -> None:
    with open_store(db) as store:
        op = load_scenario(UC1).operations[0]
        store.save_operation(op)
        v2 = replace(op.plan, version=2, reason="accepted R1", created_t_s=50.0)
        store.save_operation(replace(op, plan=v2))
        assert [p.version for p in store.load_plans("UAS1")] == [1, 2]
        assert store.latest_plan("UAS1") == v2
        assert store.load_operations()[0].plan == v2
        assert store.latest_plan("nope") is None
        store.save_plan(v2)  # the same version again is fine
        with pytest.raises(StoreError, match="other content"):
            store.save_plan(replace(v2, reason="tampered"))
        assert store.latest_plan("UAS1") == v2


def test_geofence_deactivation_and_older_track_sample(db: str | Path) -> None:
    with open_store(db) as store:
        store.save_geofence(_fence("A"))
        store.save_geofence(_fence("B"))
        assert store.deactivate_geofence("A")
        assert not store.deactivate_geofence("missing")
        assert [g.id for g in store.load_geofences()] == ["B"]
        assert [g.id for g in store.load_geofences(active_only=False)] == ["A", "B"]
        store.write_tracks([_track(5, 5.0)])
        store.write_tracks([_track(3, 3.0)])  # late sample: history only
        assert store.latest_tracks()[0].t_s == 5.0
        assert [t.t_s for t in store.track_history("UAS1", since_t_s=4.0)] == [5.0]
        assert [t.t_s for t in store.track_history("UAS1")] == [3.0, 5.0]


def test_remote_ids_keep_the_latest_of_each_source(db: str | Path) -> None:
    from gcs_utm.model import RemoteIdentity

    own = RemoteIdentity(source="sysid:1", uas_id="SN1", operator_id="OP1", updated_t_s=5.0)
    heard = RemoteIdentity(source="rid:0a0b", uas_id="SN2", lat_deg=45.0, updated_t_s=6.0)
    with open_store(db) as store:
        store.save_remote_ids([(TrackId("UAS1"), own), (TrackId("rid:0a0b"), heard)])
        store.save_remote_ids([(TrackId("UAS1"), replace(own, uas_id="OLD", updated_t_s=4.0))])
        assert store.load_remote_ids() == [(TrackId("rid:0a0b"), heard), (TrackId("UAS1"), own)]
        newer = replace(own, operator_id="OP2", updated_t_s=7.0)
        store.save_remote_ids([(TrackId("sysid:1@x"), newer)])
        assert store.load_remote_ids()[1] == (TrackId("sysid:1@x"), newer)
        assert store.count("remote_ids") == 2


def test_recommendation_states_filter(db: str | Path) -> None:
    with open_store(db) as store:
        rec = _rec()
        store.save_recommendation(rec)
        accepted = rec.transition(RecommendationState.ACCEPTED, 10.0)
        store.save_recommendation(accepted)
        assert store.load_recommendations(state=RecommendationState.PROPOSED) == []
        assert store.load_recommendations(state=RecommendationState.ACCEPTED) == [accepted]
        v2 = replace(rec, version=2)
        store.save_recommendation(v2)
        assert store.load_recommendations() == [v2]
        assert len(store.load_recommendations(latest_only=False)) == 2


def test_newer_schema_is_refused(db: str | Path) -> None:
    open_store(db).close()
    if isinstance(db, Path):
        raw_execute(db, f"PRAGMA user_version = {len(MIGRATIONS) + 1}")
    else:
        raw_execute(db, f"UPDATE gcs_utm_schema SET version = {len(MIGRATIONS) + 1}")
    with pytest.raises(StoreError, match="newer"):
        open_store(db)
    with pytest.raises(StoreError, match="schema version"):
        open_store(db, readonly=True)


def test_failed_request_in_a_batch_rolls_back_alone(db: str | Path) -> None:
    writer = StoreWriter(db)
    gate = threading.Event()
    writer.submit(lambda s: gate.wait(5))  # hold the writer so the next three share a batch
    ok1 = writer.audit(AuditEntry(t_s=1.0, actor="a", action="x", subject="s"))

    def bad(s: StoreBase) -> None:
        s.audit(AuditEntry(t_s=2.0, actor="a", action="bad", subject="s"))
        raise ValueError("boom")

    failed = writer.submit(bad)
    ok2 = writer.audit(AuditEntry(t_s=3.0, actor="a", action="y", subject="s"))
    gate.set()
    assert failed is not None
    with pytest.raises(ValueError, match="boom"):
        failed.result(5)
    assert ok1.result(5) > 0 and ok2.result(5) > 0
    writer.close()
    with open_store(db) as store:
        assert [e.action for e in store.load_audit()] == ["x", "y"]


def test_full_queue_drops_tracks_but_raises_for_audit(db: str | Path) -> None:
    writer = StoreWriter(db, StoreConfig(queue_size=2, put_timeout_s=0.1))
    gate = threading.Event()
    blocker = writer.submit(lambda s: gate.wait(5))
    # wait until the writer holds the blocker, so the queue itself is empty
    while writer._queue.qsize():
        pass
    assert writer.write_tracks([_track(0, 0.0)]) is not None
    assert writer.write_tracks([_track(1, 1.0)]) is not None
    assert writer.write_tracks([_track(2, 2.0)]) is None
    assert writer.dropped_tracks == 1
    with pytest.raises(StoreFullError):
        writer.audit(AuditEntry(t_s=1.0, actor="a", action="x", subject="s"))
    gate.set()
    assert blocker is not None
    blocker.result(5)
    writer.flush(5)
    writer.close()
    with open_store(db) as store:
        assert [t.t_s for t in store.track_history("UAS1")] == [0.0, 1.0]


async def test_async_store_durable_writes_and_reads(db: str | Path) -> None:
    rec = _rec()
    async with await AsyncStore.open(db) as store:
        await store.save_recommendation(rec)
        accepted = rec.transition(RecommendationState.ACCEPTED, 10.0)
        await store.save_recommendation(accepted)
        # durable: a separate connection sees it as soon as the await returns
        with open_store(db, readonly=True) as other:
            assert other.load_recommendations(state=RecommendationState.ACCEPTED) == [accepted]
        assert store.write_tracks([_track(0, 0.0)])
        await store.flush()
        seq = await store.audit(AuditEntry(t_s=1.0, actor="pilot", action="accept", subject="R1"))
        assert seq == 1
        assert [e.action for e in await store.load_audit()] == ["accept"]
        assert await store.load_recommendations() == [accepted]
        assert await store.read(lambda s: s.track_history("UAS1")) == [_track(0, 0.0)]
        # the loop stays responsive while writes are in flight
        ticks = 0

        async def ticker() -> None:
            nonlocal ticks
            for _ in range(20):
                ticks += 1
                await asyncio.sleep(0)

        await asyncio.gather(ticker(), *(store.save_geofence(_fence(f"G{i}")) for i in range(20)))
        assert ticks == 20
        assert len(await store.load_geofences()) == 20


_CHILD = textwrap.dedent(
    """
    import sys
    from gcs_utm.model import AuditEntry, Track, TrackId
    from gcs_utm.store import StoreWriter, StoreConfig
    w = StoreWriter(sys.argv[1], StoreConfig(batch_max=16))
    i = 0
    while True:
        i += 1
        w.write_tracks([Track(id=TrackId("T"), t_s=float(i), lat_deg=40.0, lon_deg=-3.0,
            alt_amsl_m=700.0, east_m=0.0, north_m=0.0, vel_enu_mps=(0.0, 0.0, 0.0),
            position_sigma_m=1.0, cooperative=True)])
        fut = w.audit(AuditEntry(t_s=float(i), actor="child", action="row", subject=str(i)))
        seq = fut.result()
        print(seq, flush=True)
    """
)


def test_sigkill_mid_stream_keeps_every_committed_row(db: str | Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(db)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert child.stdout is not None
    reported: list[int] = []
    try:
        for line in child.stdout:
            reported.append(int(line))
            if len(reported) >= 300:
                break
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL
    assert len(reported) >= 300
    with open_store(db) as store:
        assert store.integrity_check() == "ok"
        seqs = {int(e.subject) for e in store.load_audit()}
        assert set(reported) <= seqs
        # tracks submitted before each reported audit row were committed with or before it
        assert len(store.track_history("T")) >= len(reported)


def test_track_doc_is_the_codec_document() -> None:
    """The writer thread's fast Track encoder writes exactly the generic codec's JSON (so the
    store reads it back the same way), on odd floats and optional fields too; a value of a
    type the annotations do not promise (a NumPy integer) takes the generic path."""
    import math

    from hypothesis import given, settings
    from hypothesis import strategies as st

    from gcs_utm.model import Icao24, OperationId, Track, TrackId
    from gcs_utm.store.codec import dumps, loads
    from gcs_utm.store.sqlite import track_doc

    f = st.floats(allow_nan=True, allow_infinity=True)

    @settings(max_examples=200, deadline=None)
    @given(
        st.tuples(f, f, f, f, f, f, st.tuples(f, f, f), f),
        st.booleans(),
        st.one_of(st.none(), st.text(max_size=8)),
        st.one_of(st.none(), st.integers(0, 99)),
        st.integers(0, 10**9),
    )
    def check(
        nums: tuple[Any, ...], coop: bool, op: str | None, wp: int | None, updates: int
    ) -> None:
        t = Track(
            id=TrackId("sysid:7@10.0.0.1:14550"),
            t_s=nums[0],
            lat_deg=nums[1],
            lon_deg=nums[2],
            alt_amsl_m=nums[3],
            east_m=nums[4],
            north_m=nums[5],
            vel_enu_mps=nums[6],
            position_sigma_m=nums[7],
            cooperative=coop,
            operation_id=None if op is None else OperationId(op),
            icao24=None if op is None else Icao24("3c6444"),
            stale=not coop,
            updates=updates,
            next_waypoint=wp,
        )
        assert track_doc(t) == dumps(t)
        back = loads(Track, track_doc(t))
        assert repr(back) == repr(t) or any(math.isnan(x) for x in (*nums[:6], *nums[6], nums[7]))

    check()
    odd = Track(
        id=TrackId("a"),
        t_s=1.0,
        lat_deg=2.0,
        lon_deg=3.0,
        alt_amsl_m=4.0,
        east_m=5.0,
        north_m=6.0,
        vel_enu_mps=(1.0, 2.0, 3.0),
        position_sigma_m=1.0,
        cooperative=True,
        updates=np.int64(3),  # type: ignore[arg-type]
    )
    assert track_doc(odd) == dumps(odd)
    from gcs_utm.model import RemoteIdentity
    from gcs_utm.store import base

    assert base._TRACK_FIELDS is not None  # the fast path is on for tracks without Remote ID
    rid = RemoteIdentity(source="sysid:7", uas_id="1ABCD2345EF678XYZ", lat_deg=1.5, alt_m=None)
    with_rid = replace(odd, updates=3, remote_id=rid)
    assert track_doc(with_rid) == dumps(with_rid)
    assert loads(Track, track_doc(with_rid)) == with_rid


def test_write_tracks_large_batch_with_repeats_keeps_newest_latest_and_all_history(
    db: str | Path, tmp_path: Path
) -> None:
    """One batch larger than a statement's chunk, where ids repeat out of time order: the
    latest state is each id's newest sample, the history holds every sample (as writing them
    one by one does)."""
    batch = [_track(i, 100.0 + i, f"T{i % 700}") for i in range(1500)]
    batch += [_track(9, 50.0, "T3"), _track(9, 5000.0, "T4")]  # older, then newer, again
    with open_store(db) as store:
        store.write_tracks(batch)
        latest = {t.id: t.t_s for t in store.latest_tracks()}
        assert len(latest) == 700
        assert latest[TrackId("T3")] == 100.0 + 1403  # not the older 50.0
        assert latest[TrackId("T4")] == 5000.0
        assert latest[TrackId("T699")] == 100.0 + 1399
        assert [t.t_s for t in store.track_history("T3")] == [50.0, 103.0, 803.0, 1503.0]
        rows = store._conn.execute("SELECT COUNT(*) FROM track_history").fetchone()[0]
        assert rows == 1502
    with open_store(tmp_path / "one.sqlite3") as one:
        for t in batch:
            one.write_tracks([t])
        assert {t.id: t.t_s for t in one.latest_tracks()} == latest


def test_both_backends_have_the_same_tables_and_columns(pg_url: str, tmp_path: Path) -> None:
    """The PostgreSQL migrations are the SQLite ones, number for number: the same tables with
    the same columns in the same order."""
    assert len(PG_MIGRATIONS) == len(MIGRATIONS)
    sq = tmp_path / "db.sqlite3"
    open_store(sq).close()
    open_store(pg_url).close()
    sqlite_cols: dict[str, list[str]] = {}
    for (table,) in raw_execute(sq, "SELECT name FROM sqlite_master WHERE type='table'"):
        if str(table).startswith("sqlite_"):
            continue
        cols = raw_execute(sq, f"PRAGMA table_info({table})")
        sqlite_cols[str(table)] = [str(c[1]) for c in cols]
    pg_cols: dict[str, list[str]] = {}
    for table, column in raw_execute(
        pg_url,
        "SELECT table_name, column_name FROM information_schema.columns "
        "WHERE table_schema='public' AND table_name <> 'gcs_utm_schema' "
        "ORDER BY table_name, ordinal_position",
    ):
        pg_cols.setdefault(str(table), []).append(str(column))
    assert pg_cols == sqlite_cols


def test_a_bad_location_is_one_store_error(pg_server: object, tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="not a store location"):
        open_store("mysql://x/y")
    with pytest.raises(StoreError, match="cannot connect"):
        open_store(f"postgresql://gcs:secret@/nodb?host={tmp_path}", busy_timeout_s=1.0)
    try:
        open_store(f"postgresql://gcs:secret@/nodb?host={tmp_path}", busy_timeout_s=1.0)
    except StoreError as exc:
        assert "secret" not in str(exc)


def test_writer_survives_a_postgresql_restart(tmp_path: Path) -> None:
    """A database failover cuts every connection: the first write after it finds the old
    connection dead, is kept and retried on a new connection in the same life, and commits
    (nothing is lost, nothing half-written)."""
    from tests.store import pgserver

    server, why = pgserver.start()
    if server is None:
        pytest.skip(f"no PostgreSQL server could be started here: {why}")
    try:
        url = server.create_database()
        writer = StoreWriter(url, StoreConfig(put_timeout_s=30.0))
        epoch = writer.epoch
        assert writer.audit(AuditEntry(t_s=1.0, actor="a", action="before", subject="s")).result(5)
        server.restart()
        fut = writer.audit(AuditEntry(t_s=2.0, actor="a", action="after", subject="s"))
        assert fut.result(30) > 1
        writer.save_threat(_threat()).result(30)
        writer.close()
        with open_store(url) as store:
            assert [e.action for e in store.load_audit()] == ["before", "after"]
            assert [t.id for t in store.load_threats()] == ["T1"]
            assert raw_execute(url, "SELECT epoch FROM threats") == [(epoch,)]
    finally:
        server.stop()


def test_instances_starting_together_migrate_once(pg_url: str) -> None:
    """Several processes opening one new database at once: the advisory lock lets one migrate
    while the others wait, and all see the current schema."""
    errors: list[BaseException] = []
    versions: list[int] = []

    def open_one() -> None:
        try:
            with open_store(pg_url) as s:
                versions.append(s.schema_version)
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=open_one) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert errors == [] and versions == [len(PG_MIGRATIONS)] * 6
