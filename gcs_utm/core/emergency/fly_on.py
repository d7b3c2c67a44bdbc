"""No immediate command when every command separates the UAS less than flying on.

:func:`~.immediate.choose_commands` flies every combination of hold, climb and descend
forward and keeps the best; when none keeps the minima it took the one with the largest
separation, even when that was smaller than with no command at all. A fixed wing cannot
stop: held, it circles where it is (two turn radii of room), so its hold was often far worse
than its plan: a fixed wing on schedule was held (ratio 0.06) and circled into another UAS
(enc_1_0102_merge_overtaking, 9.3 m against 50 m). Now the combination without a
command competes too: when it keeps the larger separation EM proposes nothing, warns the
operator with the numbers, and decides the case again after ``retry_after_s`` (a command
proposed then may be better). An escalation still always carries a command: this is not
one. Pure."""

from __future__ import annotations

from dataclasses import dataclass, replace

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.model import Command, OperationId

FLY_ON = "fly on"
"""The audit's name for the combination without a command."""


@dataclass(frozen=True, slots=True)
class Choice:
    """The immediate commands chosen for the UAS of a threat (none: they fly on), with the
    separation ratio they keep and every combination tried, for the audit."""

    commands: dict[OperationId, Command]
    actions: dict[OperationId, str]
    """The audit's name of each UAS's command (``immediate.Immediate`` values)."""
    ratio: float
    clear: bool
    tried: list[dict[str, object]]
    geofences: tuple[str, ...] = ()
    """The geofences the chosen commands take their UAS into (see .command_fences)."""


def fly_on(best: Choice, none_ratio: float, best_score: float | None = None) -> Choice:
    """``best`` unless it keeps the minima or separates at least as well as no command
    (``none_ratio``; ``best_score``, when given, is how well ``best`` separates as it was
    ranked, else its ratio); else the choice without a command (empty ``commands``)."""
    score = best.ratio if best_score is None else best_score
    if best.clear or score >= none_ratio:
        return best
    tried = [*best.tried, {"commands": FLY_ON, "ratio": round(none_ratio, 3)}]
    return replace(best, commands={}, actions={}, ratio=none_ratio, tried=tried, geofences=())


def flying_on(em: EmContext, case: Case, now: float, why: str, choice: Choice) -> Decision:
    """Warn that no command is proposed because flying on separates best, with the numbers
    in the audit; the case is decided again after ``retry_after_s``."""
    text = (
        f"{why}; no immediate command: every command separates less than flying on "
        f"(ratio {choice.ratio:.2f}); decided again in {em.config.retry_after_s:.0f} s"
    )
    detail: dict[str, object] = {"reason": text, "selected": FLY_ON, "tried": choice.tried}
    case.attempt_t_s = now
    return Decision(warnings=(text,), audit=(em.audit(now, "immediate", case.threat.id, detail),))
