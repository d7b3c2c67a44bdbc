"""The recommendation and pilot-answer lifecycle of the USM (paper §4.1): proposals from EM
shown to the operators, answers matched to them, accepted plans uploaded and verified.

:class:`RecommendationLifecycle` is a part the :class:`~gcs_utm.services.usm.Usm` holds: it
is passed what it needs (the airspace, the clock, the USM's threats, counters, operators and
answer sinks, and callbacks to send commands, record, log and spawn) and does not import the
USM; it is a module of its own because it changes with the pilot prompt, not with telemetry.

Invariants:
- an answer acts on exactly the recommendation id and version it names; it is refused when
  that version is not the current one, is no longer proposed, or its deadline has passed
  (by the later of the answer's own time and the time it arrived): an expired or superseded
  version can never be accepted;
- an accept carries out exactly the option the pilot chose (``alternative_index``: one of
  ``alternatives``; None: the proposed ``selected`` one): the chosen option becomes
  ``selected`` of the accepted version, the proposed one goes back among the alternatives;
- every answer (taken, duplicate or refused) is recorded (the store's ``answers`` table) and
  audited with its outcome, who gave it, through which channel and the manoeuvre it chose;
- every version ends in a stored final state: a version EM replaced is SUPERSEDED, one EM
  let expire is EXPIRED (also when EM's notice arrives only with its successor), an accepted
  one APPLIED or FAILED; a recommendation is APPLIED only after the vehicle's readback matched;
- nothing is dropped silently: every outcome goes to the record callback and the event log.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

from gcs_utm.clock import Clock
from gcs_utm.core.deconfliction.verify import ABANDON
from gcs_utm.core.emergency.wording import proposal_text
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import (
    RECOMMENDATION_TRANSITIONS,
    Alternative,
    AuditEntry,
    Autopilot,
    Command,
    FlightPlan,
    Recommendation,
    RecommendationId,
    RecommendationState,
    SysId,
    Threat,
    ThreatId,
)
from gcs_utm.services.airspace import Airspace, AirspaceError

_log = logging.getLogger(__name__)

# ---- ports the USM talks to (implemented by adapters and services; fakes in tests)


class UploadOutcome(Protocol):
    @property
    def ok(self) -> bool: ...
    @property
    def verified(self) -> bool: ...
    @property
    def error(self) -> str: ...


class CommandOutcome(Protocol):
    @property
    def ok(self) -> bool: ...
    @property
    def error(self) -> str: ...


class VehiclePort(Protocol):
    """What the USM needs from the MAVLink side (adapters.mavlink.MavlinkHub)."""

    async def upload_plan(
        self,
        sys_id: SysId,
        plan: FlightPlan,
        *,
        autopilot: Autopilot | None = None,
        deadline_t_s: float | None = None,
        start_index: int = 0,
        climb_rate_mps: float | None = None,
        descent_rate_mps: float | None = None,
        min_speed_mps: float = 0.0,
        lands: bool = False,
    ) -> UploadOutcome: ...

    async def send_command(self, sys_id: SysId, command: Command) -> CommandOutcome: ...


class OperatorPort(Protocol):
    """Where recommendations are shown and from where answers come (dashboard, MQTT, auto)."""

    async def present(self, rec: Recommendation) -> None: ...

    async def update(self, rec: Recommendation) -> None: ...


_ENDED_BY_EM = frozenset({RecommendationState.EXPIRED, RecommendationState.SUPERSEDED})


class AnswerStatus(Enum):
    ACCEPTED = "accepted"
    DUPLICATE = "duplicate"
    REFUSED = "refused"


@dataclass(frozen=True, slots=True, kw_only=True)
class AnswerOutcome:
    status: AnswerStatus
    reason: str = ""


@dataclass(slots=True, kw_only=True)
class RecommendationRecord:
    """Bookkeeping the report and the dashboard read. ``answered_by`` / ``answered_via`` /
    ``chosen`` say who answered the current version, through which channel and (for an
    accept) which manoeuvre was chosen; ``chosen_index`` is the answer's
    ``alternative_index`` (None: the proposed option)."""

    rec: Recommendation
    threat_detected_at_s: float
    latency_ms: float
    decision: str = ""
    uploaded: bool = False
    verified: bool = False
    error: str = ""
    answered_by: str = ""
    answered_via: str = ""
    answered_t_s: float | None = None
    chosen: str = ""
    chosen_index: int | None = None
    history: list[tuple[float, str]] = field(default_factory=list)


def resume_index(plan: FlightPlan, now_s: float) -> int:
    """The plan waypoint a vehicle flies to first when ``plan`` is uploaded at ``now_s``: the
    first one still ahead in time. A new plan starts where the UAS was when it was computed;
    by the time it is accepted and uploaded (seconds later, operator's answer) the vehicle has
    moved on, and flying to that first point would turn it back (a 28 m/s fixed wing is 55 m
    past it after 2 s)."""
    wps = plan.waypoints
    for k, w in enumerate(wps):
        if w.t_s > now_s:
            return k
    return max(0, len(wps) - 1)


def options_of(rec: Recommendation) -> list[Alternative]:
    """The options a pilot chooses among, in the order the prompt numbers them: the proposed
    one (``selected``, row 0) first, then ``alternatives``."""
    return ([rec.selected] if rec.selected is not None else []) + list(rec.alternatives)


def alternative_index_of_row(rec: Recommendation, row: int) -> int | None:
    """The answer's ``alternative_index`` for the prompt's row ``row`` (None: the proposed
    option). Raises ValueError for a row the prompt does not show."""
    n = len(options_of(rec))
    if not 0 <= row < max(n, 1):
        raise ValueError(f"option {row} does not exist (0..{max(n, 1) - 1})")
    if rec.selected is None:
        return row if rec.alternatives else None
    return None if row == 0 else row - 1


def chosen_option(rec: Recommendation, alternative_index: int | None) -> Alternative | None:
    """The option an answer with ``alternative_index`` chooses."""
    if alternative_index is None:
        return rec.selected
    return rec.alternatives[alternative_index]


def with_choice(rec: Recommendation, alternative_index: int | None) -> Recommendation:
    """``rec`` with the chosen alternative as ``selected`` and the proposed one put in its
    place among the alternatives (the same options, the accepted one first)."""
    if alternative_index is None:
        return rec
    alts = list(rec.alternatives)
    chosen = alts[alternative_index]
    if rec.selected is not None:
        alts[alternative_index] = rec.selected
    else:
        del alts[alternative_index]
    return dataclasses.replace(rec, selected=chosen, alternatives=tuple(alts))


def expiry_audit(
    action: str, rec: Recommendation, t_s: float, expired_version: int | None = None
) -> AuditEntry:
    """The audit of an expiry (``recommendation_expired``: ``rec`` nobody answered) or of
    what followed it (``reproposed_after_expiry``: ``rec`` is the new version), with the
    proposal in words."""
    detail: dict[str, object] = {
        "version": rec.version,
        "operation_id": rec.operation_id,
        "proposed": proposal_text(rec),
        "deadline_t_s": rec.deadline_t_s,
    }
    if expired_version is not None:
        detail["expired_version"] = expired_version
    return AuditEntry(t_s=t_s, actor="usm", action=action, subject=rec.id, detail=detail)


@dataclass(frozen=True, slots=True, kw_only=True)
class LifecycleHooks:
    """What the lifecycle calls back into: the vehicle link (None until attached), the
    expectation of an upload's echo (VehicleOps), commands, the record, the event log and
    background tasks."""

    vehicles: Callable[[], VehiclePort | None]
    expect_upload: Callable[[SysId, FlightPlan | None], None]
    execute_command: Callable[[Command, str], Awaitable[bool]]
    record: Callable[[object], None]
    log_event: Callable[[str, str], None]
    spawn: Callable[[Awaitable[None]], None]


def _what(rec: Recommendation) -> str:
    if rec.selected is not None:
        return rec.selected.maneuver.value
    return rec.command.kind.value if rec.command is not None else "none"


class RecommendationLifecycle:
    """Proposals, answers, uploads (see the module docstring). The containers passed in are
    the USM's own (shared, not copied): ``threats`` (read), ``counters`` (``answers_refused``,
    ``uploads_ok``, ``uploads_failed`` incremented), ``operators`` and ``answer_sinks``
    (attached to later)."""

    def __init__(
        self,
        airspace: Airspace,
        clock: Clock,
        *,
        upload_attempts: int,
        threats: Mapping[ThreatId, Threat],
        counters: dict[str, int],
        operators: Sequence[OperatorPort],
        answer_sinks: Sequence[Callable[[Recommendation, bool], Awaitable[None]]],
        hooks: LifecycleHooks,
    ) -> None:
        self.airspace = airspace
        self.clock = clock
        self.upload_attempts = upload_attempts
        self.threats = threats
        self.counters = counters
        self._operators = operators
        self._answer_sinks = answer_sinks
        self._hooks = hooks
        self._record = hooks.record
        self.log_event = hooks.log_event
        self.recommendations: dict[RecommendationId, RecommendationRecord] = {}
        self.plan_check: Callable[[Recommendation], str] | None = None
        """Asked right before an accepted plan is uploaded: why it must not be ("" when it
        may; EM's re-check against the airspace as it is now, core.emergency.recheck). A
        reason fails the recommendation, and EM decides again."""

    # ---- decisions from EM ----------------------------------------------------------------
    async def on_recommendation(self, rec: Recommendation) -> None:
        now = self.clock.now_s()
        old = self.recommendations.get(rec.id)
        if old is not None and rec.version <= old.rec.version:
            # EM repeats a version it already sent. Its final state (expired, superseded)
            # is taken when ours is still proposed: EM's notice of an expiry may come only
            # with the next version, and that version must not leave this one "proposed".
            if (
                rec.version == old.rec.version
                and rec.state in _ENDED_BY_EM
                and old.rec.state is RecommendationState.PROPOSED
            ):
                if rec.state is RecommendationState.EXPIRED:
                    old.decision = "expired"
                    why = "without an answer (deadline passed)"
                else:
                    why = f"by EM ({rec.reason})" if rec.reason else "by EM"
                await self._set_state(old, rec.state, why)
            return
        if old is not None and old.rec.state is RecommendationState.PROPOSED:
            await self._set_state(old, RecommendationState.SUPERSEDED, f"by v{rec.version}")
        if old is not None and old.rec.state is RecommendationState.EXPIRED:
            self._record(expiry_audit("reproposed_after_expiry", rec, now, old.rec.version))
        threat = self.threats.get(rec.threat_id)
        detected = threat.detected_at_s if threat is not None else rec.created_t_s
        speed = self.clock.speed
        record = RecommendationRecord(
            rec=rec,
            threat_detected_at_s=detected,
            latency_ms=max(0.0, (rec.created_t_s - detected) * 1000.0 / speed)
            if speed != float("inf")
            else 0.0,
        )
        if old is not None:
            record.history = old.history
        record.history.append((now, f"proposed v{rec.version}"))
        self.recommendations[rec.id] = record
        self._record(rec)
        self.log_event(
            "recommendation",
            f"{rec.id} v{rec.version} for {rec.operation_id}: {_what(rec)} "
            f"({rec.threat_kind.value}), deadline in {rec.deadline_t_s - now:.0f} s",
        )
        for op in self._operators:
            await op.present(rec)

    async def on_superseded(self, rec_id: RecommendationId) -> None:
        record = self.recommendations.get(rec_id)
        if record is None or record.rec.state is not RecommendationState.PROPOSED:
            return
        await self._set_state(record, RecommendationState.SUPERSEDED, "by EM")

    async def on_expired(self, rec_id: RecommendationId) -> None:
        record = self.recommendations.get(rec_id)
        if record is None or record.rec.state is not RecommendationState.PROPOSED:
            return
        record.decision = "expired"
        await self._set_state(
            record, RecommendationState.EXPIRED, "without an answer (deadline passed)"
        )

    # ---- pilot answers --------------------------------------------------------------------
    async def answer(self, a: PilotAnswer) -> AnswerOutcome:
        """An operator's answer (dashboard, line prompt, MQTT, auto): matched to the exact id
        and version; an accept carries out the option it names."""
        record = self.recommendations.get(a.recommendation_id)
        outcome = self._check_answer(record, a)
        chosen = None
        if record is not None and outcome.status is not AnswerStatus.REFUSED:
            chosen = chosen_option(record.rec, a.alternative_index)
        maneuver = "" if chosen is None else chosen.maneuver.value
        self._record(a)
        self._record(
            AuditEntry(
                t_s=a.t_s,
                actor=f"operator:{a.operator}",
                action=f"answer_{a.decision.value}",
                subject=a.recommendation_id,
                detail={
                    "version": a.version,
                    "source": a.source,
                    "alternative_index": a.alternative_index,
                    "maneuver": maneuver if a.decision is PilotDecision.ACCEPT else "",
                    "received_t_s": self.clock.now_s(),
                    "outcome": outcome.status.value,
                    "reason": outcome.reason,
                },
            )
        )
        if outcome.status is not AnswerStatus.ACCEPTED or record is None:
            if outcome.status is AnswerStatus.REFUSED:
                self.counters["answers_refused"] += 1
                self.log_event(
                    "answer",
                    f"{a.recommendation_id} v{a.version} {a.decision.value} by {a.operator} "
                    f"refused: {outcome.reason}",
                )
            return outcome
        record.answered_by = a.operator
        record.answered_via = a.source
        record.answered_t_s = a.t_s
        who = f"by {a.operator} ({a.source})"
        if a.decision is PilotDecision.REJECT:
            record.decision = "rejected"
            await self._set_state(record, RecommendationState.REJECTED, who)
            for sink in self._answer_sinks:
                await sink(record.rec, False)
            return outcome
        record.decision = "accepted"
        record.chosen = maneuver
        record.chosen_index = a.alternative_index
        record.rec = with_choice(record.rec, a.alternative_index)
        choice = "proposed option" if a.alternative_index is None else "pilot's choice"
        await self._set_state(
            record,
            RecommendationState.ACCEPTED,
            f"{maneuver or _what(record.rec)} ({choice}) {who}",
        )
        for sink in self._answer_sinks:
            await sink(record.rec, True)
        self._hooks.spawn(self._apply(record))
        return outcome

    def _check_answer(self, record: RecommendationRecord | None, a: PilotAnswer) -> AnswerOutcome:
        refused = AnswerStatus.REFUSED
        if record is None:
            return AnswerOutcome(status=refused, reason="unknown recommendation")
        rec = record.rec
        reason = self._sender_problem(rec, a)
        if reason:
            return AnswerOutcome(status=refused, reason=reason)
        if rec.state is not RecommendationState.PROPOSED:
            same = (
                record.decision == "accepted"
                and a.decision is PilotDecision.ACCEPT
                and a.alternative_index == record.chosen_index
            ) or (record.decision == "rejected" and a.decision is PilotDecision.REJECT)
            if same:
                return AnswerOutcome(status=AnswerStatus.DUPLICATE, reason="already answered")
            return AnswerOutcome(status=refused, reason=f"recommendation is {rec.state.value}")
        reason = self._content_problem(rec, a)
        if reason:
            return AnswerOutcome(status=refused, reason=reason)
        return AnswerOutcome(status=AnswerStatus.ACCEPTED)

    def _sender_problem(self, rec: Recommendation, a: PilotAnswer) -> str:
        """Why the answer is not for this version or not from its operator ("" if it is)."""
        if a.version != rec.version:
            return f"version {a.version} is not the current version {rec.version}"
        op = self.airspace.operations.get(rec.operation_id)
        if op is not None and a.source == "mqtt" and a.operator not in (op.operator, "admin"):
            return f"operator {a.operator!r} does not fly {rec.operation_id}"
        return ""

    def _content_problem(self, rec: Recommendation, a: PilotAnswer) -> str:
        """Why a pending recommendation cannot take the answer: too late, or an alternative
        it does not have ("" if it can)."""
        # the later of the answer's own time and its arrival: a sender whose clock runs
        # behind cannot extend the deadline
        if max(a.t_s, self.clock.now_s()) > rec.deadline_t_s:
            return "deadline passed"
        index = a.alternative_index
        if (
            a.decision is PilotDecision.ACCEPT
            and index is not None
            and not 0 <= index < len(rec.alternatives)
        ):
            return (
                f"alternative_index {index} does not exist ({len(rec.alternatives)} alternatives)"
            )
        return ""

    async def _apply(self, record: RecommendationRecord) -> None:
        """Carry out an accepted recommendation: command, or upload + readback + new plan."""
        rec = record.rec
        try:
            op = self.airspace.operation(rec.operation_id)
        except AirspaceError as exc:
            await self._fail(record, str(exc))
            return
        if rec.command is not None and (rec.selected is None or rec.selected.plan is None):
            await self._set_state(record, RecommendationState.UPLOADING, "sending command")
            ok = await self._hooks.execute_command(rec.command, f"recommendation {rec.id}")
            if ok:
                record.verified = True
                await self._set_state(record, RecommendationState.APPLIED, "command acknowledged")
            else:
                await self._fail(record, "command not acknowledged")
            return
        plan = rec.selected.plan if rec.selected is not None else None
        if plan is None:
            # advisory only (e.g. keep plan / warn): nothing to send
            await self._set_state(record, RecommendationState.APPLIED, "advisory")
            return
        vehicles = self._hooks.vehicles()
        if vehicles is None or op.sys_id is None:
            await self._fail(record, "no MAVLink link to this vehicle")
            return
        problem = "" if self.plan_check is None else self.plan_check(rec)
        if problem:
            await self._fail(record, f"not uploaded: {problem}")
            return
        maneuver = rec.selected.maneuver.value if rec.selected is not None else ""
        new_plan = dataclasses.replace(
            plan,
            operation_id=op.id,
            version=op.plan.version + 1,
            created_t_s=self.clock.now_s(),
            reason=f"{rec.threat_kind.value}: {maneuver}",
        )
        await self._set_state(
            record, RecommendationState.UPLOADING, f"{maneuver} as plan v{new_plan.version}"
        )
        error = ""
        self._hooks.expect_upload(op.sys_id, new_plan)
        for attempt in range(1, self.upload_attempts + 1):
            result = await vehicles.upload_plan(
                op.sys_id,
                new_plan,
                autopilot=op.autopilot,
                deadline_t_s=None,
                start_index=resume_index(new_plan, self.clock.now_s()),
                climb_rate_mps=op.performance().climb_rate_mps,
                descent_rate_mps=op.performance().descent_rate_mps,
                min_speed_mps=op.performance().min_speed_mps,
                # return home, a landing site: the plan ends on the ground, a landing there
                lands=rec.selected is not None and rec.selected.maneuver in ABANDON,
            )
            record.uploaded = record.uploaded or result.ok
            if result.ok and result.verified:
                record.verified = True
                break
            error = result.error or "readback did not match"
            self.log_event("upload", f"{rec.id} attempt {attempt} failed: {error}")
        if not record.verified:
            self._hooks.expect_upload(op.sys_id, None)
            self.counters["uploads_failed"] += 1
            await self._fail(record, error)
            return
        self.counters["uploads_ok"] += 1
        try:
            self.airspace.replace_plan(new_plan)
        except AirspaceError as exc:  # a newer plan landed meanwhile: keep the newer one
            _log.warning("plan of %s not installed: %s", op.id, exc)
        # installed: a later echo matches the operation's own plan; an expectation left
        # standing would hide a pilot's later upload of this same mission
        self._hooks.expect_upload(op.sys_id, None)
        await self._set_state(
            record, RecommendationState.APPLIED, f"{maneuver}: mission verified by readback"
        )

    async def _fail(self, record: RecommendationRecord, error: str) -> None:
        record.error = error
        await self._set_state(record, RecommendationState.FAILED, error)

    async def _set_state(
        self, record: RecommendationRecord, state: RecommendationState, reason: str
    ) -> None:
        """Move ``record`` to ``state``; ``reason`` completes "<id> v<n> <state> <reason>"
        (e.g. "superseded by v2", "accepted go_up ... by dashboard")."""
        now = self.clock.now_s()
        rec = record.rec
        if state not in RECOMMENDATION_TRANSITIONS.get(rec.state, frozenset()):
            # e.g. ACCEPTED -> APPLIED directly is allowed by the model; anything else is a bug
            _log.error("recommendation %s: %s -> %s refused", rec.id, rec.state, state)
            return
        record.rec = rec.transition(state, now, reason)
        record.history.append((now, f"{state.value} v{rec.version}: {reason}"))
        self._record(record.rec)
        if state is RecommendationState.EXPIRED:
            self._record(expiry_audit("recommendation_expired", rec, now))
        self.log_event("recommendation", f"{rec.id} v{rec.version} {state.value} {reason}")
        for op in self._operators:
            await op.update(record.rec)

    async def expire_due(self) -> None:
        """Mark proposals whose deadline has passed as EXPIRED (EM re-plans on its side)."""
        now = self.clock.now_s()
        for record in list(self.recommendations.values()):
            rec = record.rec
            if rec.state is RecommendationState.PROPOSED and rec.deadline_t_s <= now:
                record.decision = "expired"
                await self._set_state(
                    record, RecommendationState.EXPIRED, "without an answer (deadline passed)"
                )

    def pending(self) -> list[Recommendation]:
        return [
            r.rec
            for r in self.recommendations.values()
            if r.rec.state is RecommendationState.PROPOSED
        ]
