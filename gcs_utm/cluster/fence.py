"""Lease fencing of the writes of region-owned rows.

Leases expire on the database clock and a member that cannot renew stops (fail-stop), but a
member that *stalls* (paused, swapped out, a long GC) past its lease expiry does not know it
until its next lease round: meanwhile a standby took the region over (the lease generation
increased), and the stalled member's queued writes would land on the new owner's operations.

So every write of a row that an operation's region owns (the operation, its plan versions,
its recommendations) carries the generation under which this life gained that region: in
the write's own transaction the lease row is read (share-locked on PostgreSQL, so a takeover
waits for the write's commit instead of slipping in between), and the write is refused with
:class:`gcs_utm.store.FencedError` when the region's holder or generation is no longer the
one this life gained. The refusal is handed to ``on_refused`` (the cluster node audits it and
stops the instance, the same fail-stop as a lost lease).

A row of an operation whose region this life never held (the decider's filing of a
recommendation for another instance's operation) is written under this life's authority over
its own regions: it is checked against every lease this life gained, so a stale decider
cannot file either. Not fenced: a life that holds no region (nothing to check against),
threats, answers and the audit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gcs_utm.store import Connection, FencedError
from gcs_utm.store.leases import holder_of


@dataclass(frozen=True, slots=True, kw_only=True)
class Refusal:
    """One write refused by the fence."""

    operation_id: str
    region_id: str
    generation: int  # the generation this life gained the region with
    current_generation: int
    current_holder: str

    def text(self, holder: str) -> str:
        return (
            f"write for {self.operation_id} refused: {holder} gained region {self.region_id} "
            f"at lease generation {self.generation}, the lease is now generation "
            f"{self.current_generation} held by {self.current_holder or 'nobody'}"
        )


class LeaseFence:
    """The fence of one member life (``holder``). ``region_of`` maps an operation id to its
    region (None: unknown here); ``generations`` is set by the node as regions are gained and
    is never shrunk, so a region lost stays fenced at the generation it was held with."""

    def __init__(
        self,
        holder: str,
        region_of: Callable[[str], str | None],
        on_refused: Callable[[Refusal], None],
        *,
        share_lock: bool = False,
    ) -> None:
        self.holder = holder
        self._region_of = region_of
        self._on_refused = on_refused
        self._share_lock = share_lock  # PostgreSQL: share-lock the lease row read
        self.generations: dict[str, int] = {}
        self.refused = 0

    def gained(self, region_id: str, generation: int) -> None:
        # replaced, never mutated: the writer thread reads it
        self.generations = {**self.generations, region_id: generation}

    def __call__(self, c: Connection, op_id: str) -> None:
        """Raise FencedError when a lease this write relies on was taken over: the lease of
        ``op_id``'s region when this life gained that region, else (a decision filed for
        another instance's operation, made under this life's authority over its own
        regions) every lease this life gained."""
        region_id = self._region_of(op_id)
        generations = self.generations
        if region_id is not None and region_id in generations:
            self._check(c, op_id, region_id, generations[region_id])
            return
        for held_region, held in sorted(generations.items()):
            self._check(c, op_id, held_region, held)

    def _check(self, c: Connection, op_id: str, region_id: str, held: int) -> None:
        row = holder_of(c, region_id, share_lock=self._share_lock)
        if row == (self.holder, held):
            return
        refusal = Refusal(
            operation_id=op_id,
            region_id=region_id,
            generation=held,
            current_generation=0 if row is None else row[1],
            current_holder="" if row is None else row[0],
        )
        self.refused += 1
        self._on_refused(refusal)
        raise FencedError(refusal.text(self.holder))


__all__ = ["LeaseFence", "Refusal"]
