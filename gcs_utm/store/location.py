"""Where a store lives: a SQLite file path (the embedded default) or a PostgreSQL URL.

``[store] url = "postgresql://user@host/db"`` selects the shared backend; empty keeps the SQLite
file (``[store] path`` or ``serve --db``). The PostgreSQL module, and with it psycopg, is
imported only when such a URL is opened.
"""

from __future__ import annotations

from pathlib import Path

from gcs_utm.store.base import StoreBase, StoreError
from gcs_utm.store.sqlite import Store

_PG_SCHEMES = ("postgresql://", "postgres://")


def is_postgres(location: str | Path) -> bool:
    """True for a ``postgresql://`` (or ``postgres://``) URL."""
    return isinstance(location, str) and location.startswith(_PG_SCHEMES)


def describe(location: str | Path) -> str:
    """``location`` for a message: a URL without its password."""
    if is_postgres(location):
        from gcs_utm.store.postgres import redact

        return redact(str(location))
    return str(location)


def open_store(
    location: str | Path,
    *,
    readonly: bool = False,
    synchronous: str = "normal",
    busy_timeout_s: float = 5.0,
    statement_timeout_s: float = 0.0,
) -> StoreBase:
    """The store at ``location``: PostgreSQL for a ``postgresql://`` URL, else the SQLite file
    (``synchronous`` applies to SQLite only; ``busy_timeout_s`` is SQLite's lock wait and
    PostgreSQL's connect timeout; ``statement_timeout_s`` > 0, PostgreSQL only, makes the
    server cancel a statement running longer)."""
    if is_postgres(location):
        try:
            from gcs_utm.store.postgres import PgStore
        except ImportError as exc:
            raise StoreError(str(exc)) from exc
        return PgStore(
            str(location),
            readonly=readonly,
            connect_timeout_s=busy_timeout_s,
            statement_timeout_s=statement_timeout_s,
        )
    if isinstance(location, str) and "://" in location:
        raise StoreError(
            f"{location.split('://', 1)[0]}://: not a store location (expected a SQLite file "
            "path or a postgresql:// URL)"
        )
    return Store(
        location, readonly=readonly, synchronous=synchronous, busy_timeout_s=busy_timeout_s
    )


__all__ = ["describe", "is_postgres", "open_store"]
