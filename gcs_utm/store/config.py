"""Settings of the store (section ``[store]``)."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class StoreConfig:
    """The Data Base: a SQLite file in WAL mode or a shared PostgreSQL, one writer thread."""

    path: str = setting("gcs_utm.sqlite3", "SQLite database file (created if absent)")
    url: str = setting(
        "",
        "shared PostgreSQL store instead of the SQLite file, e.g. "
        "'postgresql://gcs@db.example/utm' (needs gcs-utm[postgres]); empty: the SQLite file",
    )
    journal: str = setting(
        "gcs_utm.store-journal",
        "local file keeping the writes a PostgreSQL store could not take before the service "
        "stopped (database unreachable); the next start replays it. One file per instance",
    )
    queue_size: int = setting(
        10_000, "writer queue capacity in write requests; track history drops when full", min=1
    )
    batch_max: int = setting(500, "most write requests committed in one transaction", min=1)
    put_timeout_s: float = setting(
        5.0,
        "how long a must-keep write (decision, audit, plan) waits for queue space before raising",
        min=0.0,
        unit="s",
    )
    synchronous: str = setting(
        "normal",
        "SQLite synchronous mode: 'normal' survives a process crash (WAL), 'full' also a "
        "power loss",
    )
    busy_timeout_s: float = setting(
        5.0,
        "how long a connection waits for a lock held by another (PostgreSQL: to connect)",
        min=0.0,
        unit="s",
    )
    statement_timeout_s: float = setting(
        30.0,
        "PostgreSQL: the server cancels a writer statement running longer, and ends the "
        "writer's session when it stays this long inside a transaction without a statement "
        "(a stalled writer); the batch is then retried on a new connection. 0: no bound. "
        "A cluster member (serve --cluster) bounds it by [cluster] lease_s",
        min=0.0,
        unit="s",
    )

    def __post_init__(self) -> None:
        if self.url and not self.url.startswith(("postgresql://", "postgres://")):
            raise ValueError(f"store.url: expected a postgresql:// URL or empty, got {self.url!r}")
        if self.synchronous not in ("normal", "full"):
            raise ValueError(
                f"store.synchronous: expected 'normal' or 'full', got {self.synchronous!r}"
            )
