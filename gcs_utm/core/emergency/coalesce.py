"""Repeated escalations of the same thing are one escalation, updated, not a new alarm.

A case that ends in an escalation is retried every ``retry_after_s`` (and a condition that
closes and opens again gets a new threat id), so the same escalation came back every cycle:
on the generated set 353 escalations in 200 encounters, 218 of them in 25 fence
encounters, mostly one UAS's "no feasible alternative ... hold proposed" every 30 s. A
pilot swamped by repeats misses the one that is new.

An escalation is *the same* as an earlier one when its text is, less the threat ids and the
numbers in it (:func:`escalation_key`): the same UAS, the same cause and the same proposed
command kind; a different UAS, cause or command is something new and is escalated. A repeat
within ``emergency.escalation_window_s`` of the escalation it repeats does not escalate
again: it becomes a warning that updates it (the latest text, how many repeats, since
when) and an ``escalation_updated`` audit entry. Its recommendations (the proposed
command) go out as before. After the window the next repeat escalates again (a persisting
problem is raised again that often). Pure: time is passed in.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

from gcs_utm.core.emergency.decision import ACTOR, Decision
from gcs_utm.model import AuditEntry

_THREAT_ID = re.compile(r"\bE\d+-T\d+-[A-Z]+\b")
_NUMBER = re.compile(r"(?<![A-Za-z0-9_.])-?\d+(?:\.\d+)?")


def escalation_key(text: str) -> str:
    """What an escalation says, less its threat ids and numbers (times, ratios, altitudes):
    UAS names and words stay."""
    return _NUMBER.sub("#", _THREAT_ID.sub("T", text))


@dataclass(slots=True)
class _Raised:
    t_s: float
    repeats: int = 0


@dataclass(slots=True)
class EscalationCoalescer:
    """Turns repeats of an escalation within ``window_s`` into updates (module docstring)."""

    window_s: float
    _raised: dict[str, _Raised] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.window_s >= 0.0:  # also refuses NaN
            raise ValueError(f"escalation window: {self.window_s!r} s is not >= 0")

    def apply(self, decision: Decision, now: float) -> Decision:
        """``decision`` with each repeated escalation turned into an update."""
        if not decision.escalations:
            return decision
        kept: list[str] = []
        updates: list[str] = []
        audit: list[AuditEntry] = []
        for text in decision.escalations:
            key = escalation_key(text)
            raised = self._raised.get(key)
            if raised is None or now - raised.t_s >= self.window_s:
                self._raised[key] = _Raised(t_s=now)
                kept.append(text)
                continue
            raised.repeats += 1
            note = f"escalation update ({raised.repeats} since t={raised.t_s:.1f}): {text}"
            updates.append(note)
            detail: dict[str, object] = {"text": text, "repeats": raised.repeats}
            detail["raised_t_s"] = raised.t_s
            tid = _THREAT_ID.search(text)
            subject = tid.group(0) if tid else text[:80]
            audit.append(
                AuditEntry(
                    t_s=now,
                    actor=ACTOR,
                    action="escalation_updated",
                    subject=subject,
                    detail=detail,
                )
            )
        return replace(
            decision,
            escalations=tuple(kept),
            warnings=decision.warnings + tuple(updates),
            audit=decision.audit + tuple(audit),
        )
