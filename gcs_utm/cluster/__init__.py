"""Several gcs-utm instances sharing one airspace (docs/scale-out.md).

- :mod:`.regions`: the region map, grid cells with a halo margin (pure);
- :mod:`.lease`: region leases in the shared store (one holder per region);
- :mod:`.fence`: lease fencing of the writes of region-owned rows;
- :mod:`.member`: the lease thread that holds this instance's regions and takes over
  orphaned ones;
- :mod:`.resume`: what an instance loads from the store when it gains a region;
- :mod:`.exchange`: tracks of each region's operations over MQTT to the neighbours;
- :mod:`.policy`: who decides a threat seen by several instances;
- :mod:`.node`: all of it attached to one serving runtime (``serve --cluster``).

The rows behind leases, the region map and recommendation versions are the store's
(:mod:`gcs_utm.store.leases`, :mod:`gcs_utm.store.versions`).
"""
