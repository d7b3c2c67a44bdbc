"""The private PostgreSQL server of the store tests, for the cluster tests."""

from tests.store.conftest import db, pg_server, pg_url

__all__ = ["db", "pg_server", "pg_url"]
