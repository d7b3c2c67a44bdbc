"""The airspace picture the services share: operations (with their current plan version) and
geofences. One instance per running UTM, owned by the event loop (no locks: only coroutines
on one loop touch it). Every change is handed to a persistence callback (the store), so a
restart resumes from the same picture.

Snapshots are assembled here from this state plus tracking's consistent (tracks, prediction)
pair, so Monitoring and EM/TD see one time-consistent view (paper §4.4).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Iterable, Mapping

from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Geofence,
    GeofenceId,
    Operation,
    OperationId,
    OperationState,
    Position,
    PredictedTrajectories,
    SysId,
    Track,
    TrackId,
)
from gcs_utm.services.ground_vehicles import grounded_tracks

_log = logging.getLogger(__name__)


class AirspaceError(ValueError):
    """A change the airspace refuses (unknown operation, stale plan version, ...)."""


TrackSource = Callable[[], tuple[Mapping[TrackId, Track], PredictedTrajectories | None]]


class Airspace:
    """Operations and geofences, with change notification.

    ``on_operation``/``on_plan``/``on_geofence`` are called after each accepted change (the
    app wires them to the store and to tracking, which needs plans for prediction).
    """

    def __init__(
        self,
        *,
        on_operation: Callable[[Operation], None] | None = None,
        on_plan: Callable[[FlightPlan], None] | None = None,
        on_geofence: Callable[[Geofence, bool], None] | None = None,
    ) -> None:
        self._operations: dict[OperationId, Operation] = {}
        self._geofences: dict[GeofenceId, Geofence] = {}
        self._on_operation = on_operation
        self._on_plan = on_plan
        self._on_geofence = on_geofence
        self.version = 0
        """Increases on every change; consumers compare it to skip rework."""
        self._sys_index: dict[SysId, OperationId] = {}
        self._sys_index_version = -1
        # per system id, from the vehicle's own messages: True in the air, False on the ground
        # (absent: it reports no state); not a change of the picture (no version). It is the
        # state of the operation that system id flies (by_sys_id).
        self._airborne: dict[SysId, bool] = {}

    # ---- queries --------------------------------------------------------------------------
    @property
    def operations(self) -> dict[OperationId, Operation]:
        return dict(self._operations)

    def operation(self, op_id: OperationId) -> Operation:
        try:
            return self._operations[op_id]
        except KeyError:
            raise AirspaceError(f"unknown operation {op_id!r}") from None

    def by_sys_id(self, sys_id: SysId) -> Operation | None:
        """The operation flown by MAVLink system ``sys_id``: the most recently filed one if
        several (a vehicle that flies again), as Tracking associates it."""
        if self._sys_index_version != self.version:
            index = {op.sys_id: op.id for op in self._operations.values() if op.sys_id is not None}
            self._sys_index = index
            self._sys_index_version = self.version
        op_id = self._sys_index.get(sys_id)
        return None if op_id is None else self._operations[op_id]

    def geofences(self, *, active_at_s: float | None = None) -> tuple[Geofence, ...]:
        """All geofences, or those not yet expired at ``active_at_s`` (a geofence that starts
        later is kept: Monitoring checks it in 4D against the predicted times)."""
        fences = self._geofences.values()
        if active_at_s is None:
            return tuple(fences)
        return tuple(g for g in fences if g.end_t_s is None or g.end_t_s >= active_at_s)

    def set_airborne(self, sys_id: SysId, airborne: bool | None) -> None:
        """The vehicle flying ``sys_id`` is in the air (True), on the ground (False) or
        reports no state (None), as its own messages say (:mod:`.flight_state`)."""
        if airborne is None:
            self._airborne.pop(sys_id, None)
        else:
            self._airborne[sys_id] = airborne

    def airborne(self, op_id: OperationId) -> bool | None:
        """Whether the operation's vehicle is in the air (None: no state, or the operation
        is not the one its system id flies)."""
        op = self._operations.get(op_id)
        if op is None or op.sys_id is None:
            return None
        flown = self.by_sys_id(op.sys_id)
        return self._airborne.get(op.sys_id) if flown is not None and flown.id == op_id else None

    def _flown(self, up: bool) -> frozenset[OperationId]:
        ops = (self.by_sys_id(s) for s, flag in self._airborne.items() if flag is up)
        return frozenset(op.id for op in ops if op is not None)

    def airborne_ids(self) -> frozenset[OperationId]:
        """The operations whose vehicle is in the air."""
        return self._flown(True)

    # ---- changes --------------------------------------------------------------------------
    def load(self, operations: Iterable[Operation], geofences: Iterable[Geofence]) -> None:
        """Initial state (from a scenario or the store); no notifications."""
        for op in operations:
            self._operations[op.id] = op
        for g in geofences:
            self._geofences[g.id] = g
        self.version += 1

    def add_operation(self, op: Operation) -> None:
        if op.id in self._operations:
            raise AirspaceError(f"operation {op.id!r} already exists")
        self._operations[op.id] = op
        self.version += 1
        if self._on_operation:
            self._on_operation(op)
        if self._on_plan:
            self._on_plan(op.plan)

    def set_state(self, op_id: OperationId, state: OperationState) -> Operation:
        op = self.operation(op_id)
        if op.state is state:
            return op
        new = dataclasses.replace(op, state=state)
        self._operations[op_id] = new
        self.version += 1
        _log.info("operation %s: %s -> %s", op_id, op.state.value, state.value)
        if self._on_operation:
            self._on_operation(new)
        return new

    def set_home(self, op_id: OperationId, home: Position) -> Operation:
        """The operation's vehicle has this home (its HOME_POSITION when it armed)."""
        op = self.operation(op_id)
        if op.home == home:
            return op
        new = dataclasses.replace(op, home=home)
        self._operations[op_id] = new
        self.version += 1
        _log.info("operation %s: home %s", op_id, home)
        if self._on_operation:
            self._on_operation(new)
        return new

    def replace_plan(self, plan: FlightPlan, *, home: Position | None = None) -> Operation:
        """Install ``plan`` as the operation's current plan (and ``home`` as its home, when
        given: a vehicle that reported a new one). Its version must be newer."""
        op = self.operation(plan.operation_id)
        if plan.version <= op.plan.version:
            raise AirspaceError(
                f"operation {op.id}: plan version {plan.version} is not newer than "
                f"{op.plan.version}"
            )
        new = dataclasses.replace(op, plan=plan, next_waypoint=0, home=home or op.home)
        self._operations[op.id] = new
        self.version += 1
        if self._on_plan:
            self._on_plan(plan)
        if self._on_operation:
            self._on_operation(new)
        return new

    def add_geofence(self, g: Geofence) -> bool:
        """Add or replace a geofence; False if an identical one is already there."""
        old = self._geofences.get(g.id)
        if old == g:
            return False
        self._geofences[g.id] = g
        self.version += 1
        if self._on_geofence:
            self._on_geofence(g, True)
        return True

    def remove_geofence(self, geofence_id: GeofenceId) -> bool:
        g = self._geofences.pop(geofence_id, None)
        if g is None:
            return False
        self.version += 1
        if self._on_geofence:
            self._on_geofence(g, False)
        return True

    def forget_operation(self, op_id: OperationId) -> bool:
        """Drop an operation from memory (the store keeps it): one that ended long ago, so
        that a day of traffic does not accumulate (gcs_utm.services.retention)."""
        if self._operations.pop(op_id, None) is None:
            return False
        self.version += 1
        return True

    def snapshot(self, t_s: float, tracks: TrackSource) -> AirspaceSnapshot:
        """One consistent view at ``t_s``: tracking's (tracks, prediction) pair is taken at
        once, then joined with the operations, the geofences not expired at ``t_s`` and which
        operations are in the air or on the ground."""
        track_map, prediction = tracks()
        return AirspaceSnapshot(
            t_s=t_s,
            operations=dict(self._operations),
            tracks=track_map,
            geofences=self.geofences(active_at_s=t_s),
            prediction=prediction,
            airborne=self._flown(True),
            grounded=self._flown(False),
            grounded_tracks=grounded_tracks(
                track_map, {s for s, up in self._airborne.items() if not up}
            ),
        )
