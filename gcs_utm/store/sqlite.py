"""The embedded backend: one SQLite file in WAL mode (the default store).

Invariants:
- WAL journal, so one writer and any number of readers never block each other, and a commit
  survives a killed process (``synchronous = NORMAL``) or a power loss (``FULL``);
- the schema is :data:`gcs_utm.store.schema.MIGRATIONS`, its number in ``PRAGMA user_version``;
  a file newer than this code is refused.

The typed API is :class:`gcs_utm.store.base.StoreBase`. A :class:`Store` belongs to the thread
that uses it; the asyncio side goes through :class:`gcs_utm.store.writer.AsyncStore`.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from gcs_utm.store.base import StoreBase, StoreError, track_doc
from gcs_utm.store.codec import decode, encode
from gcs_utm.store.schema import MIGRATIONS


class Store(StoreBase):
    """Typed access to one SQLite database file. ``readonly`` opens it for reading only (it
    must already exist and be migrated)."""

    _begin_sql = "BEGIN IMMEDIATE"
    _now_sql = "SELECT (julianday('now') - 2440587.5) * 86400.0"

    def __init__(
        self,
        path: str | Path,
        *,
        readonly: bool = False,
        synchronous: str = "normal",
        busy_timeout_s: float = 5.0,
    ) -> None:
        self.path = Path(path)
        self.where = str(self.path)
        self.readonly = readonly
        self._init_state()
        if self.path.is_dir():
            raise StoreError(f"{self.path}: is a directory, not a store file")
        try:
            self._conn = self._open(readonly, synchronous, busy_timeout_s)
        except sqlite3.DatabaseError as exc:  # OperationalError included: not a database, no access
            raise StoreError(f"{self.path}: cannot be used as a store: {exc}") from exc

    def _open(self, readonly: bool, synchronous: str, busy_timeout_s: float) -> sqlite3.Connection:
        if readonly:
            uri = f"file:{self.path.resolve()}?mode=ro"
            conn = sqlite3.connect(uri, uri=True, isolation_level=None, check_same_thread=False)
        else:
            conn = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
        self._conn = conn
        self.max_params = conn.getlimit(sqlite3.SQLITE_LIMIT_VARIABLE_NUMBER)
        try:
            conn.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
            if not readonly:
                mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
                if str(mode).lower() != "wal":
                    raise StoreError(f"{self.path}: cannot switch to WAL (journal_mode={mode})")
                sync = "FULL" if synchronous == "full" else "NORMAL"
                conn.execute(f"PRAGMA synchronous = {sync}")
                conn.execute("PRAGMA foreign_keys = ON")
                self._migrate()
            else:
                version = self.schema_version
                if version != len(MIGRATIONS):
                    raise StoreError(
                        f"{self.path}: schema version {version}, this code needs {len(MIGRATIONS)}"
                    )
        except BaseException:
            conn.close()
            raise
        return conn

    @property
    def schema_version(self) -> int:
        return int(self._conn.execute("PRAGMA user_version").fetchone()[0])

    def _migrate(self) -> None:
        version = self.schema_version
        if version > len(MIGRATIONS):
            raise StoreError(
                f"{self.path}: schema version {version} is newer than this code "
                f"({len(MIGRATIONS)}); refusing to write it"
            )
        for number in range(version + 1, len(MIGRATIONS) + 1):
            # executescript commits first; the DDL and the version bump are one transaction.
            self._conn.executescript(
                f"BEGIN IMMEDIATE; {MIGRATIONS[number - 1]};"
                f" PRAGMA user_version = {number}; COMMIT;"
            )

    def integrity_check(self) -> str:
        return str(self._conn.execute("PRAGMA integrity_check").fetchone()[0])


def table_row_counts(db_path: Path) -> dict[str, int]:
    """Rows per table of a SQLite store file, read-only (``gcs-utm bench soak``'s census)."""
    con = sqlite3.connect(f"file:{db_path}?mode=ro", uri=True)
    try:
        names = [
            r[0]
            for r in con.execute("SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")
        ]
        return {n: int(con.execute(f'SELECT COUNT(*) FROM "{n}"').fetchone()[0]) for n in names}
    finally:
        con.close()


__all__ = ["Store", "StoreError", "decode", "encode", "table_row_counts", "track_doc"]
