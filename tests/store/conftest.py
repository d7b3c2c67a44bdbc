"""Store fixtures: ``db`` is a fresh store location on each backend (a SQLite file, then a
database on a private PostgreSQL server), so a test taking it runs against both."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.store import pgserver


@pytest.fixture(scope="session")
def pg_server() -> Iterator[pgserver.PgServer]:
    server, why = pgserver.start()
    if server is None:
        pytest.skip(f"no PostgreSQL server could be started here: {why}")
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def pg_url(pg_server: pgserver.PgServer) -> str:
    """A new empty database on the private server."""
    return pg_server.create_database()


@pytest.fixture(params=["sqlite", "postgresql"])
def db(request: pytest.FixtureRequest, tmp_path: Path) -> str | Path:
    """A fresh store location: a SQLite file path or a postgresql:// URL."""
    if request.param == "sqlite":
        return tmp_path / "db.sqlite3"
    url: str = request.getfixturevalue("pg_url")
    return url


def raw_execute(db: str | Path, sql: str) -> list[tuple[object, ...]]:
    """Run one statement on the backend directly (bypassing the store), return its rows."""
    if isinstance(db, str):
        import psycopg

        with psycopg.connect(db, autocommit=True) as conn:
            cur = conn.execute(sql.encode())
            return list(cur.fetchall()) if cur.description else []
    import sqlite3

    conn2 = sqlite3.connect(db)
    try:
        rows = list(conn2.execute(sql))
        conn2.commit()
        return rows
    finally:
        conn2.close()
