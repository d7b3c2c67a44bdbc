"""Ids that stay unique across restarts.

Threat ids (Monitoring's ``T<n>-<KIND>``, the USM's ``<kind>-<n>``) come from counters that
start again at 1 in every process. Prefixing them with the store's epoch (a number the store
issues once per life, :meth:`gcs_utm.store.Store.begin_life`) makes them unique for the life
of the database: ``E3-T1-LOS`` is the first loss of separation of the third life. Everything
derived from a threat id (recommendation ids ``<threat>/<operation>``, the EM's geofence ids
``em-<threat>-<operation>``) inherits the uniqueness.

Rows written before epochs existed keep their unprefixed ids; no prefixed id can equal one of
them, because the old ids never start with ``E<digits>-``.
"""

from __future__ import annotations

import re

_PREFIX = re.compile(r"^E(\d+)-")


def life_prefix(epoch: int) -> str:
    """The prefix of every id made in life ``epoch`` (>= 1)."""
    if epoch < 1:
        raise ValueError(f"an epoch is >= 1, got {epoch}")
    return f"E{epoch}-"


def epoch_of(object_id: str) -> int | None:
    """The epoch an id was made in, or None for an id without a life prefix."""
    m = _PREFIX.match(object_id)
    return int(m.group(1)) if m else None


__all__ = ["epoch_of", "life_prefix"]
