"""What the running service forgets: operations that ended long ago and geofences that
expired long ago leave memory (the store keeps them), so that ``serve`` holds what is
current however many operations came and went (``gcs-utm bench soak``).

:class:`Retention` is swept periodically (``run``): an operation first seen ENDED at t is
forgotten at t + ``keep_s`` (``Airspace.forget_operation``), then ``on_forgotten`` tells the
parts that keep per-operation state (tracking drops the operation's track); a geofence whose
end time is more than ``keep_s`` past is removed (``Airspace.remove_geofence``). An hour
keeps every late answer, report and view of a recent flight working as before.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from gcs_utm.clock import Clock
from gcs_utm.model import OperationId, OperationState
from gcs_utm.services.airspace import Airspace

KEEP_S = 3600.0
"""Seconds an ended operation and an expired geofence stay in memory."""

SWEEP_PERIOD_S = 60.0


@dataclass(slots=True, kw_only=True)
class Retention:
    airspace: Airspace
    on_forgotten: Callable[[list[OperationId]], None] = lambda _ids: None
    keep_s: float = KEEP_S
    _ended_since: dict[OperationId, float] = field(default_factory=dict)

    def sweep(self, now_s: float) -> list[OperationId]:
        """Forget what has been over for ``keep_s``; the operations forgotten."""
        ended = {
            op.id for op in self.airspace.operations.values() if op.state is OperationState.ENDED
        }
        for op_id in self._ended_since.keys() - ended:
            del self._ended_since[op_id]  # forgotten by someone else
        forgotten = []
        for op_id in ended:
            since = self._ended_since.setdefault(op_id, now_s)
            if now_s - since >= self.keep_s:
                self.airspace.forget_operation(op_id)
                del self._ended_since[op_id]
                forgotten.append(op_id)
        for g in self.airspace.geofences():
            if g.end_t_s is not None and now_s - g.end_t_s >= self.keep_s:
                self.airspace.remove_geofence(g.id)
        if forgotten:
            self.on_forgotten(forgotten)
        return forgotten

    async def run(self, clock: Clock, period_s: float = SWEEP_PERIOD_S) -> None:
        while True:
            await clock.sleep(period_s)
            self.sweep(clock.now_s())
