"""The cluster's region map and region leases in the store: the SQL of :mod:`gcs_utm.cluster`.

A lease is a row ``(region_id, holder, epoch, generation, acquired_unix_s, expires_unix_s)``.
Acquiring and renewing are the same conditional upsert, one statement in one transaction:
the row is written only when it is free, expired, or already ours, so two instances racing
for a region can never both win (PostgreSQL serialises the upsert on the row; SQLite has one
writer). Times are the database's clock (:meth:`StoreBase.now_unix_s`), never an instance's.
``generation`` increases with every change of holder: a fencing number that tells a reader
which ownership a decision was made under. What the cluster builds on these rows (the lease
rounds, the fence, the region map check) is in :mod:`gcs_utm.cluster.lease` and
:mod:`gcs_utm.cluster.fence`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from gcs_utm.store.base import Connection, StoreBase


@dataclass(frozen=True, slots=True, kw_only=True)
class Lease:
    region_id: str
    holder: str
    epoch: int
    generation: int
    acquired_unix_s: float
    expires_unix_s: float


def file_regions(store: StoreBase, docs: Mapping[str, str]) -> dict[str, str]:
    """File each region's document unless its id is filed already, in one transaction, and
    return every filed region's document by id (what the store holds, old or new)."""
    with store.transaction() as c:
        for region_id, doc in docs.items():
            c.execute(
                "INSERT INTO regions (id, doc) VALUES (?, ?) ON CONFLICT(id) DO NOTHING",
                (region_id, doc),
            )
        return {str(i): str(d) for i, d in c.execute("SELECT id, doc FROM regions").fetchall()}


def acquire(
    store: StoreBase, region_id: str, holder: str, epoch: int, lease_s: float
) -> Lease | None:
    """Take or renew the lease of ``region_id`` for ``holder``; None while another holds it."""
    with store.transaction() as c:
        now_s = store.now_unix_s()
        row = c.execute(
            "INSERT INTO region_leases "
            "(region_id, holder, epoch, generation, acquired_unix_s, expires_unix_s) "
            "VALUES (?, ?, ?, 1, ?, ?) "
            "ON CONFLICT(region_id) DO UPDATE SET "
            "generation = CASE WHEN region_leases.holder = excluded.holder "
            "THEN region_leases.generation ELSE region_leases.generation + 1 END, "
            "acquired_unix_s = CASE WHEN region_leases.holder = excluded.holder "
            "THEN region_leases.acquired_unix_s ELSE excluded.acquired_unix_s END, "
            "holder = excluded.holder, epoch = excluded.epoch, "
            "expires_unix_s = excluded.expires_unix_s "
            "WHERE region_leases.holder = excluded.holder OR region_leases.expires_unix_s <= ? "
            "RETURNING generation, acquired_unix_s, expires_unix_s",
            (region_id, holder, epoch, now_s, now_s + lease_s, now_s),
        ).fetchone()
    if row is None:
        return None
    return Lease(
        region_id=region_id,
        holder=holder,
        epoch=epoch,
        generation=int(row[0]),
        acquired_unix_s=float(row[1]),
        expires_unix_s=float(row[2]),
    )


def release(store: StoreBase, region_id: str, holder: str) -> bool:
    """Give a region up at once (clean shutdown); False if ``holder`` did not hold it."""
    with store.transaction() as c:
        now_s = store.now_unix_s()
        cur = c.execute(
            "UPDATE region_leases SET expires_unix_s = ? WHERE region_id = ? AND holder = ?",
            (now_s, region_id, holder),
        )
        return bool(cur.rowcount > 0)


def leases(store: StoreBase) -> dict[str, Lease]:
    """Every lease row (live or expired), by region."""
    rows = store._rows(
        "SELECT region_id, holder, epoch, generation, acquired_unix_s, expires_unix_s "
        "FROM region_leases ORDER BY region_id"
    )
    return {
        str(r[0]): Lease(
            region_id=str(r[0]),
            holder=str(r[1]),
            epoch=int(r[2]),
            generation=int(r[3]),
            acquired_unix_s=float(r[4]),
            expires_unix_s=float(r[5]),
        )
        for r in rows
    }


def clear(store: StoreBase) -> None:
    """Delete every lease row (a benchmark's run starts with no owner)."""
    with store.transaction() as c:
        c.execute("DELETE FROM region_leases")


def holder_of(c: Connection, region_id: str, *, share_lock: bool) -> tuple[str, int] | None:
    """(holder, generation) of ``region_id``'s lease row read inside the caller's transaction
    ``c`` (None: no row). ``share_lock`` (PostgreSQL) keeps the row from changing until that
    transaction ends, so a takeover waits for the write it fences to commit."""
    row = c.execute(
        "SELECT holder, generation FROM region_leases WHERE region_id = ?"
        + (" FOR SHARE" if share_lock else ""),
        (region_id,),
    ).fetchone()
    return None if row is None else (str(row[0]), int(row[1]))


__all__ = ["Lease", "acquire", "clear", "file_regions", "holder_of", "leases", "release"]
