"""Recommendation version numbers that are unique across the instances of a cluster, and
the other reads a cluster member makes of the recommendations of several lives.

Two lives write versions of one recommendation id: the decider (its EM numbers them 1, 2, 3
... in its memory) and the operation's owner (it proposes the decider's version to its pilot
as the next version in its own life). Numbering each side's next version as "the last one I
know + 1" lets both pick the same number (the decider re-decides after the owner's version
was rejected), and the store refuses the second row (a life never overwrites another's row):
the re-decision never reaches the pilot.

So a life files each *new* version through :func:`allocate`: one transaction reads the
highest version of the id in the store and inserts the row at ``max(wanted, highest + 1)``;
lives allocating versions of one id are serialised (:meth:`StoreBase.lock_key`: an advisory
lock on PostgreSQL, SQLite's single writer), and a number taken anyway (a row written by the
plain upsert of another life) is skipped by ``ON CONFLICT DO NOTHING`` and a new attempt.
The number the store gave is returned; the decider keeps a map from its EM's numbers to the
filed ones (:class:`gcs_utm.cluster.decisions.DecisionRelay`).
Later state changes of a filed version are ordinary upserts by the same life
(:meth:`StoreBase.save_recommendation`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from gcs_utm.model import Recommendation, RecommendationState
from gcs_utm.store.base import Connection, StoreBase, StoreError
from gcs_utm.store.codec import dumps

# how often allocate reads the highest version again after losing a race for a number
_ATTEMPTS = 8

FenceCheck = Callable[[Connection, str], None]


def allocate(
    store: StoreBase, rec: Recommendation, epoch: int, fence: FenceCheck | None = None
) -> int:
    """File ``rec`` as a new version written by life ``epoch`` and return its version number
    (``rec.version`` when it is free and above every filed version, else the next free one).
    ``fence`` (a cluster member's lease fence) is checked in the same transaction and raises
    :class:`gcs_utm.store.FencedError` when this life no longer holds the operation's
    region."""
    for _ in range(_ATTEMPTS):
        with store.transaction() as c:
            if fence is not None:
                fence(c, rec.operation_id)
            store.lock_key(c, f"recommendation:{rec.id}")
            row = c.execute(
                "SELECT MAX(version) FROM recommendations WHERE id = ?", (rec.id,)
            ).fetchone()
            highest = 0 if row is None or row[0] is None else int(row[0])
            filed = dataclasses.replace(rec, version=max(rec.version, highest + 1))
            cur = c.execute(
                "INSERT INTO recommendations "
                "(id, version, state, threat_id, operation_id, created_t_s, doc, epoch) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT(id, version) DO NOTHING",
                (
                    filed.id,
                    filed.version,
                    filed.state.value,
                    filed.threat_id,
                    filed.operation_id,
                    filed.created_t_s,
                    dumps(filed),
                    epoch,
                ),
            )
            if cur.rowcount == 1:
                return filed.version
    raise StoreError(
        f"{store.where}: no free version of recommendation {rec.id!r} after {_ATTEMPTS} attempts"
    )


_OPEN = (RecommendationState.PROPOSED.value, RecommendationState.ACCEPTED.value)


def open_with_lives(store: StoreBase) -> list[tuple[Recommendation, int]]:
    """The latest version of every recommendation that is PROPOSED (a prompt) or ACCEPTED
    (decided, not yet carried out: an autonomous command), each with the life that wrote it:
    a member proposes the prompts and carries out the commands another life filed for its
    operations."""
    rows = store._rows(
        "SELECT doc, epoch FROM recommendations r WHERE state IN (?, ?) AND "
        "version = (SELECT MAX(version) FROM recommendations q WHERE q.id = r.id) "
        "ORDER BY created_t_s, id",
        _OPEN,
    )
    return [(store._load(Recommendation, d), int(e)) for d, e in rows]


def highest_of_life(store: StoreBase, epoch: int) -> list[tuple[str, str, int]]:
    """(id, operation id, highest version) of every recommendation that life ``epoch`` wrote
    a version of, by id (the versions a gaining life's EM may hold)."""
    rows = store._rows(
        "SELECT id, operation_id, MAX(version) FROM recommendations WHERE id IN "
        "(SELECT id FROM recommendations WHERE epoch = ?) GROUP BY id, operation_id "
        "ORDER BY id",
        (epoch,),
    )
    return [(str(i), str(op), int(v)) for i, op, v in rows]


__all__ = ["FenceCheck", "allocate", "highest_of_life", "open_with_lives"]
