"""Region leases in the shared store: one row per region, held by one instance life.

A lease is a row ``(region_id, holder, epoch, generation, acquired_unix_s, expires_unix_s)``.
Acquiring and renewing are the same conditional upsert, one statement in one transaction:
the row is written only when it is free, expired, or already ours, so two instances racing
for a region can never both win (PostgreSQL serialises the upsert on the row; SQLite has one
writer). Times are the database's clock (:meth:`StoreBase.now_unix_s`), never an instance's.
``generation`` increases with every change of holder: a fencing number that tells a reader
which ownership a decision was made under.

Invariants:
- at most one holder per region at any instant of the database clock;
- a holder that stops renewing loses the region ``lease_s`` after its last renewal, and a
  standby can then take it (the failover bound is ``lease_s`` plus one ``renew_s`` period);
- a release (clean shutdown) frees the region at once.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.cluster.regions import RegionError, RegionMap
from gcs_utm.store import StoreBase, StoreError


@dataclass(frozen=True, slots=True, kw_only=True)
class Lease:
    region_id: str
    holder: str
    epoch: int
    generation: int
    acquired_unix_s: float
    expires_unix_s: float


def publish_map(store: StoreBase, region_map: RegionMap) -> None:
    """File the region map in the store, or check that the one filed is the same: instances
    with different maps would disagree on who owns what, so a mismatch is refused."""
    wanted = {r: region_map.region_doc(r) for r in region_map.ids()}
    with store.transaction() as c:
        for region_id, doc in wanted.items():
            c.execute(
                "INSERT INTO regions (id, doc) VALUES (?, ?) ON CONFLICT(id) DO NOTHING",
                (region_id, doc),
            )
        stored = {str(i): str(d) for i, d in c.execute("SELECT id, doc FROM regions").fetchall()}
    if stored != wanted:
        extra = sorted(set(stored) - set(wanted))
        differ = sorted(r for r in wanted if stored.get(r) != wanted[r])
        raise RegionError(
            f"{store.where}: the store's region map differs from [cluster] here "
            f"(regions {', '.join(differ + extra)}); every instance must use the same map"
        )


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


def owners(store: StoreBase) -> dict[str, str]:
    """Region -> holder of every lease live now on the database clock."""
    now_s = store.now_unix_s()
    return {r: lease.holder for r, lease in leases(store).items() if lease.expires_unix_s > now_s}


__all__ = ["Lease", "StoreError", "acquire", "leases", "owners", "publish_map", "release"]
