"""How long a decision takes to reach a vehicle: the answer, then the upload of a plan or the
acknowledgement of a command, measured per vehicle (operation).

The USM knows when each recommendation was answered and when its upload or command was
acknowledged; the service hands those figures to :class:`ResponseTimes` as data (core stays
pure: no clock here). Until a vehicle has a measurement the configured figures stand:
``emergency.expected_answer_s`` (or the automatic operator's delay), ``upload_time_s`` and
:data:`COMMAND_TIME_S`. A measured figure is the slowest of the vehicle's last
:data:`WINDOW` (a decision planned on the typical figure would start inside the loss every
time the link is slow).

- a new plan starts at ``now + answer + upload + start_margin_s`` (:func:`plan_start`); the
  answer is 0 in autonomous mode and never more than the time to the deadline;
- a command acts at ``now + answer + command`` (:func:`command_at`): no mission upload, which
  is why an immediate command can help where a plan is too late.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Collection, Iterable
from dataclasses import dataclass, field

from gcs_utm.core.emergency.config import EmergencyConfig
from gcs_utm.model import OperationId, Recommendation, RecommendationId, RecommendationState

WINDOW = 5
"""Measurements kept per vehicle and figure."""
COMMAND_TIME_S = 1.0
"""Expected time from an accepted command to its acknowledgement, before one is measured."""

ANSWER, UPLOAD, COMMAND = "answer", "upload", "command"
_FIGURES = (ANSWER, UPLOAD, COMMAND)


@dataclass(slots=True)
class ResponseTimes:
    """Measured answer, upload and command times (s) per operation: the slowest of the last
    :data:`WINDOW` of each, else the configured default (see the module docstring)."""

    config: EmergencyConfig
    answer_delay_s: float | None = None
    """An automatic operator's delay (``--auto-accept``): the answer default instead of
    ``expected_answer_s``."""
    _seen: dict[tuple[str, OperationId], deque[float]] = field(default_factory=dict)
    _accepted: dict[tuple[RecommendationId, int], tuple[OperationId, float]] = field(
        default_factory=dict
    )
    """When each accepted version was accepted (and its operation), until applied or failed."""

    def observe(self, figure: str, op_id: OperationId, seconds: float) -> None:
        """Record one measured ``figure`` (answer, upload or command) for ``op_id``."""
        if figure not in _FIGURES:
            raise ValueError(f"response time: unknown figure {figure!r}, expected {_FIGURES}")
        if not seconds >= 0.0:  # also refuses NaN
            raise ValueError(f"response time {figure} of {op_id}: {seconds!r} s is not >= 0")
        self._seen.setdefault((figure, op_id), deque(maxlen=WINDOW)).append(float(seconds))

    def on_state(self, rec: Recommendation) -> None:
        """Measure from a state change of ``rec`` as the USM reports it: an answer (accepted
        or rejected) takes from its creation to then; an APPLIED plan's upload, or command's
        acknowledgement, from its acceptance (else its creation: born accepted) to then."""
        t = rec.state_t_s
        key = (rec.id, rec.version)
        if t is None:
            return
        if rec.state in (RecommendationState.ACCEPTED, RecommendationState.REJECTED):
            self.observe(ANSWER, rec.operation_id, max(0.0, t - rec.created_t_s))
            if rec.state is RecommendationState.ACCEPTED:
                self._accepted[key] = (rec.operation_id, t)
        elif rec.state is RecommendationState.APPLIED:
            since = self._accepted.pop(key, (rec.operation_id, rec.created_t_s))[1]
            plan = rec.selected is not None and rec.selected.plan is not None
            figure = COMMAND if rec.command is not None and not plan else UPLOAD
            self.observe(figure, rec.operation_id, max(0.0, t - since))
        elif rec.state is RecommendationState.FAILED:
            self._accepted.pop(key, None)

    def forget(self, op_ids: Collection[OperationId]) -> None:
        """Operations the airspace forgot (services/retention.py) take their measurements with
        them: a day of traffic must not accumulate here (``gcs-utm bench soak``)."""
        for key in [k for k in self._seen if k[1] in op_ids]:
            del self._seen[key]
        for acc in [k for k, (op_id, _) in self._accepted.items() if op_id in op_ids]:
            del self._accepted[acc]

    def measured(self) -> dict[str, dict[str, float]]:
        """What has been measured so far, for the audit: figure -> operation -> seconds."""
        out: dict[str, dict[str, float]] = {}
        for (figure, op_id), values in sorted(self._seen.items()):
            out.setdefault(figure, {})[str(op_id)] = round(max(values), 3)
        return out

    def _figure(self, figure: str, op_ids: Iterable[OperationId], default: float) -> float:
        """The slowest measured ``figure`` over ``op_ids`` (each unmeasured: ``default``)."""
        worst = None
        for op_id in op_ids:
            values = self._seen.get((figure, op_id))
            got = max(values) if values else default
            worst = got if worst is None else max(worst, got)
        return default if worst is None else worst

    def answer_s(self, op_ids: Iterable[OperationId]) -> float:
        """The expected answer (0 in autonomous mode)."""
        if self.config.autonomous:
            return 0.0
        cfg = self.config
        default = cfg.expected_answer_s if self.answer_delay_s is None else self.answer_delay_s
        return self._figure(ANSWER, op_ids, default)

    def upload_s(self, op_ids: Iterable[OperationId]) -> float:
        return self._figure(UPLOAD, op_ids, self.config.upload_time_s)

    def command_s(self, op_ids: Iterable[OperationId]) -> float:
        return self._figure(COMMAND, op_ids, COMMAND_TIME_S)

    def plan_start(self, op_ids: Iterable[OperationId], now: float, deadline_t_s: float) -> float:
        """When a plan decided ``now`` for ``op_ids`` can start: the expected answer (never
        past the deadline), the upload and ``start_margin_s``."""
        ids = tuple(op_ids)
        answer = min(max(deadline_t_s - now, 0.0), self.answer_s(ids))
        return now + answer + self.upload_s(ids) + self.config.start_margin_s

    def earliest_receipt(self, op_ids: Iterable[OperationId], now: float) -> float:
        """The earliest a vehicle can have a plan decided ``now``: an immediate answer (or the
        automatic operator's delay) plus the upload (TD's lead-in starts there)."""
        ids = tuple(op_ids)
        answer = 0.0 if self.answer_delay_s is None or self.config.autonomous else None
        if answer is None:
            answer = self.answer_s(ids)
        return now + answer + self.upload_s(ids)

    def command_at(self, op_ids: Iterable[OperationId], now: float) -> float:
        """When a command proposed ``now`` acts on the vehicle: answer plus acknowledgement."""
        ids = tuple(op_ids)
        return now + self.answer_s(ids) + self.command_s(ids)
