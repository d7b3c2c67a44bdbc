"""Lives of the store: every writing process gets a new epoch, ids carry it, and a row written
by one life is never overwritten by another (issue 21, item 1)."""

from __future__ import annotations

import asyncio
import sqlite3
from dataclasses import replace
from pathlib import Path

import pytest

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.monitor import Monitor
from gcs_utm.geo import LocalFrame
from gcs_utm.model import RecommendationState, ThreatId, ThreatStatus
from gcs_utm.store import Store, StoreError, StoreWriter, open_store
from gcs_utm.store.codec import dumps
from gcs_utm.store.ids import epoch_of, life_prefix
from gcs_utm.store.schema import MIGRATIONS
from tests.store.conftest import raw_execute
from tests.store.test_store import _rec, _threat


def _rows(db: str | Path, table: str) -> list[tuple[object, ...]]:
    return raw_execute(db, f"SELECT * FROM {table} ORDER BY 1, 2")


def test_epochs_increase_and_are_never_reused(db: str | Path) -> None:
    epochs = []
    for _ in range(3):
        with open_store(db) as s:
            epochs.append(s.begin_life())
    assert epochs == [1, 2, 3]
    # even with the rows gone, AUTOINCREMENT (an identity sequence) goes on
    raw_execute(db, "DELETE FROM lives")
    with open_store(db) as s:
        assert s.begin_life() == 4
    w = StoreWriter(db)
    try:
        assert w.epoch == 5
    finally:
        w.close()
    with open_store(db) as s:
        assert [e for e, _t, _pid in s.lives()] == [4, 5]


def test_a_later_life_never_overwrites_a_threat_or_recommendation(db: str | Path) -> None:
    threat, rec = _threat(), _rec()
    with open_store(db) as first:
        first.save_threat(threat)
        first.save_recommendation(rec)
        # the life that wrote a row updates it (a threat's and a version's life cycle)
        first.save_threat(replace(threat, status=ThreatStatus.CLOSED))
        first.save_recommendation(replace(rec, state=RecommendationState.ACCEPTED))
    before_t, before_r = _rows(db, "threats"), _rows(db, "recommendations")
    with open_store(db) as second:
        second.begin_life()
        with pytest.raises(StoreError, match="written by life 1, this is life 2"):
            second.save_threat(replace(threat, message="a new threat reusing the id"))
        with pytest.raises(StoreError, match="never overwritten"):
            second.save_recommendation(replace(rec, state=RecommendationState.PROPOSED))
        # another version of the same recommendation id is a new row, not an overwrite
        second.save_recommendation(replace(rec, version=2))
    assert _rows(db, "threats") == before_t
    assert _rows(db, "recommendations")[0] == before_r[0]
    assert len(_rows(db, "recommendations")) == 2


def test_migration_keeps_rows_of_a_store_made_before_lives(tmp_path: Path) -> None:
    """A store at schema 1 (no lives): its rows get epoch 0 and stay as they were."""
    db = tmp_path / "old.sqlite"
    threat = _threat()
    conn = sqlite3.connect(db, isolation_level=None)
    conn.executescript(f"BEGIN; {MIGRATIONS[0]}; PRAGMA user_version = 1; COMMIT;")
    conn.execute(
        "INSERT INTO threats VALUES (?, ?, ?, ?, ?)",
        (threat.id, threat.kind.value, threat.status.value, threat.detected_at_s, dumps(threat)),
    )
    conn.close()
    with Store(db) as s:
        assert s.schema_version == len(MIGRATIONS)
        assert [dumps(t) for t in s.load_threats()] == [dumps(threat)]
        with pytest.raises(StoreError, match="written by life 0"):
            s.save_threat(replace(threat, status=ThreatStatus.CLOSED))
        assert [dumps(t) for t in s.load_threats()] == [dumps(threat)]
        assert s.epoch == 1


def test_ids_carry_the_life_prefix() -> None:
    assert life_prefix(3) == "E3-"
    assert epoch_of("E3-T1-LOS/UAS2") == 3
    assert epoch_of("T1-LOS") is None
    assert epoch_of("gnss_jamming_attack-1") is None
    with pytest.raises(ValueError, match="epoch"):
        life_prefix(0)
    monitor = Monitor(LocalFrame(40.0, -3.0, 600.0), MonitoringConfig(), id_prefix="E7-")
    assert monitor.id_prefix == "E7-"
    assert ThreatId("E7-T1-CONF").startswith(monitor.id_prefix)


async def test_each_service_life_makes_its_own_threat_ids(tmp_path: Path) -> None:
    """The composition root prefixes Monitoring's and the USM's threat ids with the life the
    store writer began: the same hazard in two lives gets two ids, and both rows stay."""
    from gcs_utm.app import Persistence, build_runtime
    from gcs_utm.clock import ManualClock
    from gcs_utm.messages import HazardReport
    from gcs_utm.model import ThreatKind
    from gcs_utm.settings import Settings

    db = tmp_path / "s.sqlite"
    ids = []
    for life in (1, 2):
        store = Persistence(StoreWriter(db))
        try:
            rt = build_runtime(Settings(), ManualClock(0.0), LocalFrame(40.0, -3.0, 600.0), store)
            assert rt.monitoring.monitor.id_prefix == f"E{life}-"
            rt.usm.on_hazard(HazardReport(kind=ThreatKind.JAMMING_ATTACK, t_s=1.0, message="x"))
            for _ in range(5):
                await asyncio.sleep(0)
            (threat,) = rt.usm.threats.values()
            ids.append(threat.id)
        finally:
            await asyncio.get_running_loop().run_in_executor(None, store.close)
    assert ids[0] != ids[1] and [epoch_of(i) for i in ids] == [1, 2]
    with Store(db) as s:
        assert sorted(t.id for t in s.load_threats()) == sorted(ids)


def test_a_folder_or_a_foreign_file_is_one_store_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from gcs_utm.cli import main

    with pytest.raises(StoreError, match="is a directory"):
        Store(tmp_path)
    foreign = tmp_path / "notes.sqlite"
    foreign.write_text("not a database, just text " * 100)
    with pytest.raises(StoreError, match="cannot be used as a store: file is not a database"):
        Store(foreign)
    for db in (tmp_path, foreign):
        assert main(["serve", "--db", str(db), "--headless"]) == 2
        _out, err = capsys.readouterr()
        assert err.count("\n") == 1 and "Traceback" not in err and str(db) in err
