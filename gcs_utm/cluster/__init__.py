"""Several gcs-utm instances sharing one airspace (docs/scale-out.md): a region map of grid
cells (:mod:`.regions`, pure; its halo margin is the building block of the region exchange,
which is not built yet), region leases in the shared PostgreSQL store
(:mod:`.lease`), the member task that holds and takes over regions (:mod:`.member`) and what
an instance loads from the store when it gains a region (:mod:`.resume`)."""
