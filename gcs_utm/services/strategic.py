"""Strategic check at filing time: every plan filed into the airspace (a new operation, or a
new plan version of one) is checked against the other filed plans, and what it conflicts
with is logged as a ``strategic`` event (the operator's event log, the audit trail).

The filed plans are kept in a :class:`~gcs_utm.core.monitoring.strategic.FiledPlans` index,
so a filing costs the check of ONE plan against the plans airborne at the same time; the
others are not re-checked. The index follows the airspace through its ``on_operation``
notification; operations loaded without notification (a scenario, the store after a
restart, both before the service starts) are filed on the first notification. Operations
that have LANDED or ENDED leave the index. A conflict is a finding, not a refusal: the plan
is filed either way and Monitoring watches the pair in flight.

A UAS in the air is traffic until it lands, whatever its plan says: a plan (when filed, and
again when its operation is activated) is also checked against each airborne UAS
(``airborne``, from the vehicles' own messages) hovering at the end of its plan once that has
ended, and an airborne UAS's own plan is followed by that hover while the other plans go on
(a fixed wing's loiter circle is Monitoring's and TD's, from its track; here its circle's
centre stands for it).

With ``geofences``, each filed plan is also checked against them: a path or destination
inside an active fence is logged with the operation, the fence, the waypoint and a proposed
fix (:mod:`gcs_utm.core.monitoring.filing`); a submission over MQTT is refused for it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import replace

from gcs_utm.core.deconfliction.loitering import hover_plan
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.filing import FenceFinding, plan_in_fences
from gcs_utm.core.monitoring.strategic import FiledPlans, PlanConflict, plan_vs_plans
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan, Geofence, Operation, OperationId, OperationState

_log = logging.getLogger(__name__)

_OVER = (OperationState.LANDED, OperationState.ENDED)


class FilingCheck:
    """``check = FilingCheck(frame, config, operations=lambda: airspace.operations,
    log_event=usm.log_event)``; wire ``check.on_operation`` to the airspace's notification."""

    def __init__(
        self,
        frame: LocalFrame,
        config: MonitoringConfig,
        *,
        operations: Callable[[], Mapping[OperationId, Operation]],
        log_event: Callable[[str, str], None] | None = None,
        step_s: float = 1.0,
        airborne: Callable[[], Collection[OperationId]] | None = None,
        geofences: Callable[[], Sequence[Geofence]] | None = None,
    ) -> None:
        self._filed = FiledPlans(frame, config, step_s=step_s)
        self._frame = frame
        self._config = config
        self._airborne = airborne
        self._geofences = geofences
        self.fence_findings: dict[OperationId, list[FenceFinding]] = {}
        """The geofences each operation's current plan runs into (see :meth:`in_fences`)."""
        self._plan: dict[OperationId, FlightPlan] = {}
        self._operations = operations
        self._log_event = log_event
        self.conflicts: dict[OperationId, list[PlanConflict]] = {}
        """The conflicts found when each operation's current plan was filed."""
        self.counters = {"checked": 0, "in_conflict": 0, "errors": 0}
        self._synced = False
        self._state: dict[OperationId, OperationState] = {}

    def __len__(self) -> int:
        return len(self._filed)

    def on_operation(self, op: Operation) -> None:
        """An operation was filed or changed: (re)check its plan if it is new to the index.
        A failure of the check is logged and counted; it never stops the filing."""
        try:
            self._on_operation(op)
        except Exception:  # a bug here must not refuse a plan the airspace accepted
            self.counters["errors"] += 1
            _log.exception("strategic check of %s failed", op.id)

    def _on_operation(self, op: Operation) -> None:
        self._sync(skip=op.id)
        if op.state in _OVER:
            if self._plan.pop(op.id, None) is not None:
                self._filed.remove(op.id)
            return
        activated = op.state is OperationState.ACTIVE and self._state.get(op.id) is not op.state
        self._state[op.id] = op.state
        if self._plan.get(op.id) is op.plan:
            if activated:  # activation: UAS that ended their plan meanwhile may still be up
                self._report(op, self._after_plans(op, ()), counted=False)
            return  # a state change: the filed plan stands
        found = self._filed.check(op.plan, op)
        found += self._after_plans(op, {c.b for c in found})
        self._filed.add(op)
        self._plan[op.id] = op.plan
        self._fences(op)
        self._report(op, found)

    def _report(self, op: Operation, found: list[PlanConflict], *, counted: bool = True) -> None:
        """Keep and log the conflicts of ``op``'s plan (``counted``: a new check)."""
        if not counted and not found:
            return
        self.conflicts[op.id] = found
        self.counters["checked"] += counted
        if found:
            self.counters["in_conflict"] += 1
        for c in found:
            self._event(
                f"{op.id} plan v{op.plan.version} conflicts with {c.b}: first loss at "
                f"t={c.first_loss_t_s:.1f}, closest {c.min_distance_m:.1f} m "
                f"(horizontal {c.min_horizontal_m:.1f} m, vertical {c.min_vertical_m:.1f} m)"
            )

    def _after_plans(self, op: Operation, known: Collection[OperationId]) -> list[PlanConflict]:
        """Conflicts with airborne UAS after their plan (and of ``op`` after its own when it is
        airborne), other than with ``known``."""
        air = set(self._airborne()) if self._airborne is not None else set()
        if not air:
            return []
        ops = {i: o for i, o in self._operations().items() if i != op.id and i not in known}
        end = op.plan.end_t_s
        found = []
        hovering = [
            replace(o, plan=hover_plan(o.plan, end))
            for i, o in ops.items()
            if i in air and o.plan.end_t_s < end
        ]
        if hovering:
            found += plan_vs_plans(op.plan, op, hovering, self._frame, self._config)
        rest = [o for o in ops.values() if o.state not in _OVER and o.plan.end_t_s > end]
        if op.id in air and rest:
            last = max(o.plan.end_t_s for o in rest)
            tail = replace(op.plan, waypoints=hover_plan(op.plan, last).waypoints[-2:])
            seen = {c.b for c in found}
            rest = [o for o in rest if o.id not in seen]
            found += plan_vs_plans(tail, op, rest, self._frame, self._config)
        return found

    def _sync(self, skip: OperationId) -> None:
        """File the operations loaded without notification (once, on the first one)."""
        if self._synced:
            return
        self._synced = True
        missing = [
            o
            for o in self._operations().values()
            if o.id != skip and o.state not in _OVER and o.id not in self._plan
        ]
        if not missing:
            return
        self._filed.add_many(missing)
        for o in missing:
            self._plan[o.id] = o.plan
            self._fences(o)

    def forget_operations(self, op_ids: Collection[OperationId]) -> None:
        """Operations the airspace forgot (services/retention.py): what their filing found
        leaves memory too (a day of traffic kept one list of conflicts per operation)."""
        for op_id in op_ids:
            self.conflicts.pop(op_id, None)
            self.fence_findings.pop(op_id, None)
            self._state.pop(op_id, None)
            if self._plan.pop(op_id, None) is not None:
                self._filed.remove(op_id)

    def in_fences(self, op: Operation) -> list[FenceFinding]:
        """The active geofences ``op``'s plan runs into (none without ``geofences``). A
        plan of Tactical Deconfliction is not judged again: TD verified it against every
        fence, from its exit point on when it leaves one it is in."""
        if self._geofences is None or op.plan.reason.startswith("TD "):
            return []
        return plan_in_fences(op.plan, op, self._geofences(), self._frame)

    def _fences(self, op: Operation) -> None:
        found = self.in_fences(op)
        self.fence_findings[op.id] = found
        for f in found:
            self._event(f.message())

    def _event(self, text: str) -> None:
        if self._log_event is not None:
            self._log_event("strategic", text)
        else:
            _log.info("strategic: %s", text)
