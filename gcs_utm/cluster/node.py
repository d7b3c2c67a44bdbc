"""A serving instance as a cluster member (``serve --cluster``): the member task's regions
drive what this instance's airspace holds.

- start: the airspace holds the active geofences and no operation; operations come with the
  regions this instance gains;
- region gained (its configured region at start, or an orphan taken over): the region's
  operations, the active geofences and its pending recommendations are loaded from the store
  (:mod:`gcs_utm.cluster.resume`); each pending recommendation is proposed again as the next
  version in this life, so its pilot prompt goes on where the dead owner left it;
- region lost (the lease could not be renewed in time, or another instance holds it): this
  instance stops (fail-stop, exit code 3). It cannot know what the new owner has decided
  since, and a clean restart re-joins as a standby; carrying on would risk two instances
  deciding for the same operations.
Every gain and loss is audited (actor: this instance's lease holder name).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Protocol

from gcs_utm.clock import Clock
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.cluster.lease import Lease
from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.resume import RegionState, load_region
from gcs_utm.geo import LocalFrame
from gcs_utm.model import AuditEntry, Geofence, Operation, OperationId, Recommendation

_log = logging.getLogger(__name__)


class AirspacePort(Protocol):
    @property
    def operations(self) -> Mapping[OperationId, Operation]: ...

    def load(self, operations: Iterable[Operation], geofences: Iterable[Geofence]) -> None: ...


class TrackingPort(Protocol):
    def set_operations(self, operations: Iterable[Operation]) -> None: ...


class UsmPort(Protocol):
    async def on_recommendation(self, rec: Recommendation) -> None: ...

    def log_event(self, kind: str, text: str) -> None: ...


class ClusterNode:
    """Connects a :class:`ClusterMember` to one runtime's airspace, tracking and USM."""

    def __init__(
        self,
        location: str | Path,
        config: ClusterConfig,
        *,
        instance: str,
        epoch: int,
        frame: LocalFrame,
        clock: Clock,
        airspace: AirspacePort,
        tracking: TrackingPort,
        usm: UsmPort,
        record: Callable[[object], None],
        on_fail: Callable[[str], None],
    ) -> None:
        self.member = ClusterMember(
            location,
            config,
            instance=instance,
            epoch=epoch,
            on_gained=self._gained,
            on_lost=self._lost,
        )
        self._frame = frame
        self._clock = clock
        self._airspace = airspace
        self._tracking = tracking
        self._usm = usm
        self._record = record
        self._on_fail = on_fail
        self.resumed: dict[str, RegionState] = {}

    async def _gained(self, region_id: str, lease: Lease | None) -> None:
        region_map = self.member.map
        state = await self.member.read(lambda s: load_region(s, region_id, region_map, self._frame))
        assert isinstance(state, RegionState)
        self.resumed[region_id] = state
        known = set(self._airspace.operations)
        self._airspace.load(state.operations, state.geofences)
        self._tracking.set_operations(self._airspace.operations.values())
        generation = lease.generation if lease is not None else 0
        for rec in state.pending:
            await self._usm.on_recommendation(
                dataclasses.replace(
                    rec,
                    version=rec.version + 1,
                    reason=f"resumed by {self.member.holder} (region {region_id}, lease "
                    f"generation {generation})",
                )
            )
        new_ops = [op.id for op in state.operations if op.id not in known]
        text = (
            f"region {region_id} held (generation {generation}): {len(new_ops)} operations, "
            f"{len(state.geofences)} geofences, {len(state.pending)} pending recommendations"
        )
        _log.info("cluster: %s", text)
        self._usm.log_event("cluster", text)
        self._record(
            AuditEntry(
                t_s=self._clock.now_s(),
                actor=self.member.holder,
                action="region_gained",
                subject=region_id,
                detail={
                    "generation": generation,
                    "operations": [str(i) for i in new_ops],
                    "pending": [f"{r.id} v{r.version}" for r in state.pending],
                },
            )
        )

    async def _lost(self, region_id: str, _lease: Lease | None) -> None:
        self._record(
            AuditEntry(
                t_s=self._clock.now_s(),
                actor=self.member.holder,
                action="region_lost",
                subject=region_id,
            )
        )
        self._on_fail(f"region {region_id} lost: this instance stops (fail-stop)")


__all__ = ["ClusterNode"]
