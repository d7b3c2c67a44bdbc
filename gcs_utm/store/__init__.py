"""The paper's Data Base: SQLite in WAL mode with versioned migrations.

:class:`Store` is the synchronous typed API (one connection, one thread);
:class:`StoreWriter` is the single writer thread with a bounded, batched queue;
:class:`AsyncStore` is what asyncio services use (durable awaits, non-blocking reads).
"""

from gcs_utm.store.config import StoreConfig
from gcs_utm.store.sqlite import Store, StoreError
from gcs_utm.store.writer import AsyncStore, StoreFullError, StoreWriter

__all__ = ["AsyncStore", "Store", "StoreConfig", "StoreError", "StoreFullError", "StoreWriter"]
