"""The MQTT tests' stand-in for the USM's answer matching: :class:`AnswerBook` keeps the
recommendations a :class:`~mqtt_helpers.FakeUsm` was told about and answers pilots by the same
id + version rules as the USM (production: :mod:`gcs_utm.services.recommendations`, whose rules
``tests/mqtt/test_answer_rules.py`` checks), so that the bridge and pilot-session tests can run
without a USM. Pure, no I/O, no clock (``t_s`` is passed in).

Rules:

- an answer names a recommendation id **and** version; only the current version of that id
  can be answered; an older version is refused as superseded, a newer one as unknown;
- only the operator the recommendation was sent to may answer it (when registered with one);
- the first valid answer wins; repeating it (same decision and alternative) is a
  ``duplicate`` and changes nothing; a different answer afterwards is refused;
- an answer whose ``t_s`` is after the deadline is refused as expired (deadline inclusive);
- ``alternative_index`` on an accept must name one of the recommendation's alternatives.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from adapters.mqtt.answers import AnswerOutcome, AnswerStatus
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import Recommendation, RecommendationId, RecommendationState


@dataclass(slots=True)
class _Entry:
    rec: Recommendation
    operator: str | None
    answer: PilotAnswer | None = None
    older_versions: set[int] = field(default_factory=set)


class AnswerBook:
    """The recommendations waiting for an answer, and the answers given."""

    def __init__(self) -> None:
        self._entries: dict[RecommendationId, _Entry] = {}

    def register(self, rec: Recommendation, operator: str | None = None) -> None:
        """Make ``rec`` (this id and version) the one answers are matched against. A new
        version of a known id supersedes the old one; re-registering the same version
        keeps a recorded answer."""
        old = self._entries.get(rec.id)
        if old is not None and old.rec.version == rec.version:
            old.rec = rec
            old.operator = operator if operator is not None else old.operator
            return
        older = set() if old is None else {*old.older_versions, old.rec.version}
        self._entries[rec.id] = _Entry(rec=rec, operator=operator, older_versions=older)

    def forget(self, rec_id: RecommendationId) -> None:
        self._entries.pop(rec_id, None)

    def get(self, rec_id: RecommendationId) -> Recommendation | None:
        entry = self._entries.get(rec_id)
        return None if entry is None else entry.rec

    def operator_of(self, rec_id: RecommendationId) -> str | None:
        entry = self._entries.get(rec_id)
        return None if entry is None else entry.operator

    def answer(self, a: PilotAnswer, t_s: float) -> AnswerOutcome:
        """Match ``a`` (received at ``t_s``; the later of ``t_s`` and ``a.t_s`` counts for
        the deadline, so a pilot clock running behind cannot extend it)."""
        entry = self._entries.get(a.recommendation_id)
        if entry is None:
            return _outcome(a, AnswerStatus.REFUSED, "unknown recommendation", None)
        rec = entry.rec
        mismatch = _mismatch(entry, a)
        if mismatch is not None:
            return _outcome(a, *mismatch, rec.state)
        answered_t_s = max(t_s, a.t_s)
        if answered_t_s > rec.deadline_t_s:
            reason = f"expired: deadline {rec.deadline_t_s:.3f} passed at {answered_t_s:.3f}"
            entry.rec = rec.transition(RecommendationState.EXPIRED, answered_t_s, reason)
            return _outcome(a, AnswerStatus.REFUSED, reason, RecommendationState.EXPIRED)
        if a.alternative_index is not None and not 0 <= a.alternative_index < len(rec.alternatives):
            reason = (
                f"alternative_index {a.alternative_index} out of range "
                f"(0..{len(rec.alternatives) - 1})"
            )
            return _outcome(a, AnswerStatus.REFUSED, reason, rec.state)
        new_state = (
            RecommendationState.ACCEPTED
            if a.decision is PilotDecision.ACCEPT
            else RecommendationState.REJECTED
        )
        entry.rec = rec.transition(new_state, answered_t_s, f"pilot {a.decision.value}")
        entry.answer = a
        return _outcome(a, AnswerStatus.ACCEPTED, "", new_state)


def _mismatch(entry: _Entry, a: PilotAnswer) -> tuple[AnswerStatus, str] | None:
    """Why ``a`` cannot answer ``entry``'s recommendation whatever the time: another
    operator, another version, an answer already taken (the same one again: a duplicate), a
    recommendation no longer proposed. None when it can."""
    rec = entry.rec
    if entry.operator is not None and a.operator != entry.operator:
        return (
            AnswerStatus.REFUSED,
            f"operator {a.operator!r} may not answer for operator {entry.operator!r}",
        )
    if a.version != rec.version:
        if a.version in entry.older_versions or a.version < rec.version:
            reason = f"version {a.version} was superseded by version {rec.version}"
        else:
            reason = f"unknown version {a.version} (current is {rec.version})"
        return AnswerStatus.REFUSED, reason
    prev = entry.answer
    if prev is not None:
        if prev.decision is a.decision and prev.alternative_index == a.alternative_index:
            return AnswerStatus.DUPLICATE, "already answered"
        return AnswerStatus.REFUSED, f"already answered: {prev.decision.value}"
    if rec.state is not RecommendationState.PROPOSED:
        return AnswerStatus.REFUSED, f"recommendation is {rec.state.value}"
    return None


def _outcome(
    a: PilotAnswer, status: AnswerStatus, reason: str, state: RecommendationState | None
) -> AnswerOutcome:
    return AnswerOutcome(
        status=status,
        recommendation_id=a.recommendation_id,
        version=a.version,
        decision=a.decision,
        reason=reason,
        state=state,
    )
