"""The shared backend: PostgreSQL (or an engine speaking its protocol) through psycopg 3.

Several gcs-utm instances may write one database (docs/scale-out.md). The schema is
:data:`gcs_utm.store.schema.PG_MIGRATIONS`, the same tables as SQLite's, number for number;
the applied number is the row of ``gcs_utm_schema``. Migrating takes a transaction-scoped
advisory lock, so instances starting together migrate once, and a database newer than this
code is refused.

psycopg is imported here only, and this module only when a ``postgresql://`` location is
opened (:func:`gcs_utm.store.open_store`): the embedded SQLite default needs no driver.
Driver errors are translated to :class:`StoreError` at this boundary.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from functools import lru_cache
from typing import Any
from urllib.parse import urlsplit, urlunsplit

try:
    import psycopg
except ImportError as exc:  # pragma: no cover - depends on the installed extras
    raise ImportError(
        "a postgresql:// store needs psycopg 3: pip install 'gcs-utm[postgres]'"
    ) from exc

from gcs_utm.store.base import TABLES, Connection, StoreBase, StoreError
from gcs_utm.store.schema import PG_MIGRATIONS

# First number of the advisory locks of StoreBase.lock_key ("gcsk" in ASCII)
_KEY_LOCKS = 0x6763736B
# Key of the advisory lock held while migrating ("gcsutm" in ASCII): any fixed number that
# no other application of the database uses.
_MIGRATE_LOCK = 0x67637375746D
# PostgreSQL's limit of bound parameters in one statement (a 16-bit count).
_MAX_PARAMS = 65_535


def one_line(exc: BaseException) -> str:
    """libpq's message on one line (it spreads a failure and its hint over several)."""
    return "; ".join(part.strip() for part in str(exc).splitlines() if part.strip())


def redact(url: str) -> str:
    """``url`` without its password, for messages and logs."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    netloc = parts.netloc.replace(f":{parts.password}@", ":***@", 1)
    return urlunsplit(parts._replace(netloc=netloc))


@lru_cache(maxsize=256)
def _paramstyle(sql: str) -> str:
    """The common dialect's ``?`` placeholders as psycopg's ``%s`` (a literal ``%`` doubled).
    The typed API's SQL has no ``?`` inside string literals."""
    return re.sub(r"\?", "%s", sql.replace("%", "%%"))


# TCP keepalive of every connection: a peer that vanished (host loss, a cut network) is
# found within idle + interval * count seconds instead of the kernel's two hours. Ignored
# on a unix socket, where the kernel reports a closed peer at once.
KEEPALIVE = {
    "keepalives": 1,
    "keepalives_idle": 5,
    "keepalives_interval": 2,
    "keepalives_count": 3,
}


def _session_options(statement_timeout_s: float) -> dict[str, Any]:
    """libpq keywords of a connection: keepalive, and with ``statement_timeout_s`` > 0 a
    server-side ``statement_timeout`` (a statement running longer is cancelled by the server
    and fails with a StoreError, so no call waits on a lock or a stalled server for ever) and
    the same ``idle_in_transaction_session_timeout`` (a client that stalls inside a
    transaction, between two statements, has its session ended by the server: the locks it
    holds, e.g. a lease fence's ``FOR SHARE``, cannot outlive the bound either)."""
    opts: dict[str, Any] = dict(KEEPALIVE)
    if statement_timeout_s > 0:
        ms = max(1, round(statement_timeout_s * 1000))
        opts["options"] = f"-c statement_timeout={ms} -c idle_in_transaction_session_timeout={ms}"
    return opts


class _PgConnection:
    """A psycopg connection behind the one ``execute`` the typed API calls."""

    def __init__(self, conn: psycopg.Connection[Any], where: str) -> None:
        self.raw = conn
        self._where = where

    def execute(self, sql: str, params: Sequence[Any] = (), /) -> psycopg.Cursor[Any]:
        try:
            return self.raw.execute(_paramstyle(sql), params)
        except psycopg.Error as exc:  # lost connection, constraint, bad SQL: one error type
            raise StoreError(f"{self._where}: {one_line(exc)}") from exc

    def script(self, sql: str) -> None:
        """Several statements, no parameters (migrations)."""
        self.raw.execute(sql.encode())

    def close(self) -> None:
        self.raw.close()

    @property
    def broken(self) -> bool:
        return bool(self.raw.broken or self.raw.closed)


class PgStore(StoreBase):
    """Typed access to one PostgreSQL database. ``readonly`` sets every transaction of the
    session read-only (the schema must already be current)."""

    _conn: _PgConnection
    _now_sql = "SELECT extract(epoch FROM clock_timestamp())::float8"

    def lock_key(self, c: Connection, key: str) -> None:
        # the two-number form, in a space of its own: never the migration lock's key
        c.execute(f"SELECT pg_advisory_xact_lock({_KEY_LOCKS}, hashtext(?))", (key,))

    def __init__(
        self,
        url: str,
        *,
        readonly: bool = False,
        connect_timeout_s: float = 10.0,
        statement_timeout_s: float = 0.0,
    ) -> None:
        self.url = url
        self.where = redact(url)
        self.readonly = readonly
        self.max_params = _MAX_PARAMS
        self._init_state()
        try:
            raw = psycopg.connect(
                url,
                autocommit=True,
                connect_timeout=max(1, round(connect_timeout_s)),
                **_session_options(statement_timeout_s),
            )
        except psycopg.Error as exc:
            raise StoreError(f"{self.where}: cannot connect: {one_line(exc)}") from exc
        self._conn = _PgConnection(raw, self.where)
        try:
            if readonly:
                self._conn.execute("SET default_transaction_read_only = on")
                if self.schema_version != len(PG_MIGRATIONS):
                    raise StoreError(
                        f"{self.where}: schema version {self.schema_version}, this code needs "
                        f"{len(PG_MIGRATIONS)}"
                    )
            else:
                self._migrate()
        except BaseException:
            raw.close()
            raise

    @property
    def broken(self) -> bool:
        """True once the connection is lost (the writer then opens a new one)."""
        return self._conn.broken

    @property
    def schema_version(self) -> int:
        exists = self._conn.execute("SELECT to_regclass('gcs_utm_schema') IS NOT NULL").fetchone()
        if exists is None or not exists[0]:
            return 0
        row = self._conn.execute("SELECT version FROM gcs_utm_schema").fetchone()
        return 0 if row is None else int(row[0])

    def _migrate(self) -> None:
        with self.transaction() as c:
            # a migration (or the wait for another instance's) is not bounded by the
            # session's statement timeout: stopping it halfway helps nobody
            c.execute("SET LOCAL statement_timeout = 0")
            c.execute("SELECT pg_advisory_xact_lock(?)", (_MIGRATE_LOCK,))
            c.execute("CREATE TABLE IF NOT EXISTS gcs_utm_schema (version INTEGER NOT NULL)")
            row = c.execute("SELECT version FROM gcs_utm_schema").fetchone()
            if row is None:
                c.execute("INSERT INTO gcs_utm_schema (version) VALUES (0)")
            version = 0 if row is None else int(row[0])
            if version > len(PG_MIGRATIONS):
                raise StoreError(
                    f"{self.where}: schema version {version} is newer than this code "
                    f"({len(PG_MIGRATIONS)}); refusing to write it"
                )
            # DDL is transactional in PostgreSQL: every step and the version bump commit
            # together, or none does.
            for number in range(version + 1, len(PG_MIGRATIONS) + 1):
                self._conn.script(PG_MIGRATIONS[number - 1])
                c.execute("UPDATE gcs_utm_schema SET version = ?", (number,))

    def integrity_check(self) -> str:
        """'ok' when the schema is current and every table answers a scan. PostgreSQL keeps
        its own files consistent (WAL, checksums when the cluster has them); this checks what
        this code depends on, not the disk pages."""
        if self.schema_version != len(PG_MIGRATIONS):
            return f"schema version {self.schema_version}, expected {len(PG_MIGRATIONS)}"
        for table in sorted(TABLES):
            self._conn.execute(f"SELECT COUNT(*) FROM {table}").fetchone()
        return "ok"


__all__ = ["PgStore", "redact"]
