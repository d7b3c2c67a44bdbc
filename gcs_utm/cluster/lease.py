"""Region leases in the shared store: one row per region, held by one instance life.

The rows and their statements are the store's (:mod:`gcs_utm.store.leases`: ``acquire``,
``release``, ``leases``, re-exported here as the cluster's lease API); this module checks the
filed region map and says who owns what now. Acquiring and renewing are the same conditional
upsert in one transaction, written only when the row is free, expired or already ours, so two
instances racing for a region can never both win. Times are the database's clock
(:meth:`StoreBase.now_unix_s`), never an instance's. ``generation`` increases with every
change of holder: a fencing number that tells a reader which ownership a decision was made
under.

Invariants:
- at most one holder per region at any instant of the database clock;
- a holder that stops renewing loses the region ``lease_s`` after its last renewal, and a
  standby can then take it (the failover bound is ``lease_s`` plus one ``renew_s`` period);
- a release (clean shutdown) frees the region at once.
"""

from __future__ import annotations

from gcs_utm.cluster.regions import RegionError, RegionMap
from gcs_utm.store import StoreBase, StoreError
from gcs_utm.store.leases import Lease, acquire, file_regions, leases, release


def publish_map(store: StoreBase, region_map: RegionMap) -> None:
    """File the region map in the store, or check that the one filed is the same: instances
    with different maps would disagree on who owns what, so a mismatch is refused."""
    wanted = {r: region_map.region_doc(r) for r in region_map.ids()}
    stored = file_regions(store, wanted)
    if stored != wanted:
        extra = sorted(set(stored) - set(wanted))
        differ = sorted(r for r in wanted if stored.get(r) != wanted[r])
        raise RegionError(
            f"{store.where}: the store's region map differs from [cluster] here "
            f"(regions {', '.join(differ + extra)}); every instance must use the same map"
        )


def owners(store: StoreBase) -> dict[str, str]:
    """Region -> holder of every lease live now on the database clock."""
    now_s = store.now_unix_s()
    return {r: lease.holder for r, lease in leases(store).items() if lease.expires_unix_s > now_s}


__all__ = ["Lease", "StoreError", "acquire", "leases", "owners", "publish_map", "release"]
