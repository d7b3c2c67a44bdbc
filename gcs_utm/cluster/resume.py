"""What an instance loads from the shared store when it gains a region.

An operation belongs to the region of its departure (its plan's first waypoint) for its whole
flight: the region's owner holds its vehicle link, uploads its plans and answers for it, and
a border crossing does not move it. The
airspace's geofences are everyone's: all active ones are loaded. A *pending* recommendation
is the latest version of one of the region's operations that is still PROPOSED: the dead
owner's prompt, which the new owner proposes again as the next version in its own life (a
life never rewrites another's row, see :mod:`gcs_utm.store.ids`), keeping its deadline.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.cluster.regions import RegionMap
from gcs_utm.geo import LocalFrame
from gcs_utm.model import Geofence, Operation, OperationId, Recommendation, RecommendationState
from gcs_utm.store import StoreBase, versions


@dataclass(frozen=True, slots=True, kw_only=True)
class RegionState:
    """A region's share of the store, as its new owner resumes it."""

    region_id: str
    operations: tuple[Operation, ...]
    geofences: tuple[Geofence, ...]
    pending: tuple[Recommendation, ...]
    # the highest stored version of each recommendation of the region's operations that the
    # gaining life wrote a version of (the ones its EM may hold, decided for them as foreign)
    highest: tuple[tuple[str, int], ...] = ()


def departure_region(op: Operation, frame: LocalFrame, region_map: RegionMap) -> str:
    first = op.plan.waypoints[0]
    east_m, north_m = frame.point_to_local(first.lat_deg, first.lon_deg)
    return region_map.region_of(east_m, north_m)


def load_region(
    store: StoreBase, region_id: str, region_map: RegionMap, frame: LocalFrame, epoch: int = 0
) -> RegionState:
    """The operations departing in ``region_id``, the active geofences and the region's
    pending recommendations (read in one call on the caller's thread); with ``epoch`` (the
    gaining life), the highest version of each recommendation of those operations it wrote
    a version of."""
    ops = tuple(
        op
        for op in store.load_operations()
        if op.plan.waypoints and departure_region(op, frame, region_map) == region_id
    )
    ids = {op.id for op in ops}
    pending = tuple(
        r
        for r in store.load_recommendations(state=RecommendationState.PROPOSED)
        if r.operation_id in ids
    )
    return RegionState(
        region_id=region_id,
        operations=ops,
        geofences=tuple(store.load_geofences(active_only=True)),
        pending=pending,
        highest=_highest(store, ids, epoch) if epoch else (),
    )


def _highest(store: StoreBase, op_ids: set[OperationId], epoch: int) -> tuple[tuple[str, int], ...]:
    return tuple(
        (i, v) for i, op, v in versions.highest_of_life(store, epoch) if OperationId(op) in op_ids
    )


__all__ = ["RegionState", "departure_region", "load_region"]
