"""The paper's Data Base: SQLite in WAL mode (embedded default) or PostgreSQL (shared by
several instances), the same schema and migrations on both.

:class:`StoreBase` is the synchronous typed API (one connection, one thread), opened by
:func:`open_store` from a file path or a ``postgresql://`` URL (:class:`Store` is the SQLite
backend); :class:`StoreWriter` is the single writer thread with a bounded, batched queue;
:class:`AsyncStore` is what asyncio services use (durable awaits, non-blocking reads).
"""

from gcs_utm.store.base import Connection, FencedError, StoreBase, StoreError
from gcs_utm.store.config import StoreConfig
from gcs_utm.store.location import describe, is_postgres, open_store
from gcs_utm.store.sqlite import Store
from gcs_utm.store.writer import AsyncStore, StoreFullError, StoreWriter

__all__ = [
    "AsyncStore",
    "Connection",
    "FencedError",
    "Store",
    "StoreBase",
    "StoreConfig",
    "StoreError",
    "StoreFullError",
    "StoreWriter",
    "describe",
    "is_postgres",
    "open_store",
]
