"""What ``gcs-utm pilot`` prints and reads: a recommendation (JSON as it arrives over MQTT)
as a few readable lines, the pilot's typed answer, gcs-utm's acknowledgement and state
changes. Pure functions of their arguments (no I/O), so they are tested on their own.

Options are numbered like the console prompt of ``gcs-utm run``
(``gcs_utm.services.recommendations.options_of``): row 0 is the proposed option
(``selected``), then ``alternatives``; row N is sent as the answer's ``alternative_index``
(None for the proposed option).
"""

from __future__ import annotations

import datetime
import re
from dataclasses import dataclass
from typing import Any

HELP = (
    "answer with: a (accept the proposed option), a N (accept option N), r (reject); "
    "details (the raw scores); command a UAS with: hold|land|rtl|resume UAS, then y"
)

# the scoring terms Tactical Deconfliction appends to an alternative's detail ("k=v, ...")
_TERM = re.compile(r"([a-z_]+)=(-?[0-9.]+(?:e-?[0-9]+)?)")


@dataclass(frozen=True, slots=True)
class Choice:
    """The pilot's typed answer: ``accept`` with the option row (None: the proposed one), or
    not ``accept`` (reject)."""

    accept: bool
    row: int | None = None


def parse_choice(line: str) -> Choice:
    """``a`` / ``a N`` / ``r`` (also ``accept``/``reject``, any case). Raises ValueError
    saying what is accepted."""
    words = line.strip().lower().split()
    if words and words[0] in ("a", "accept") and len(words) <= 2:
        if len(words) == 1:
            return Choice(accept=True)
        if words[1].isdigit():
            return Choice(accept=True, row=int(words[1]))
    elif words in (["r"], ["reject"]):
        return Choice(accept=False)
    raise ValueError(f"{line.strip()!r} is not an answer; {HELP}")


def options(rec: dict[str, Any]) -> list[dict[str, Any]]:
    """The options a pilot chooses among, in prompt order: ``selected`` then alternatives."""
    selected = rec.get("selected")
    alternatives = [a for a in rec.get("alternatives") or [] if isinstance(a, dict)]
    return ([selected] if isinstance(selected, dict) else []) + alternatives


def alternative_index(rec: dict[str, Any], row: int | None) -> int | None:
    """The answer's ``alternative_index`` for prompt row ``row`` (None: the proposed option).
    Raises ValueError for a row not shown."""
    if row is None:
        return None
    n = len(options(rec))
    if not 0 <= row < n:
        raise ValueError(f"option {row} does not exist (options 0..{n - 1}); {HELP}")
    if not isinstance(rec.get("selected"), dict):
        return row
    return None if row == 0 else row - 1


def _words(value: object) -> str:
    """An enum value as words: ``LOSS_OF_SEPARATION`` -> ``loss of separation``."""
    return str(value).lower().replace("_", " ")


def _terms(detail: str) -> dict[str, float]:
    return {k: float(v) for k, v in _TERM.findall(detail)}


def option_summary(alt: dict[str, Any]) -> str:
    """One line: the manoeuvre, extra distance and time and the minimum separation (when the
    alternative's detail carries them), cost and risk."""
    detail = str(alt.get("detail") or "")
    terms = _terms(detail)
    parts = [_words(alt.get("maneuver", "?"))]
    if "extra_distance_m" in terms:
        parts.append(f"{terms['extra_distance_m']:+.0f} m")
    if "extra_time_s" in terms:
        parts.append(f"{terms['extra_time_s']:+.1f} s")
    if "min_separation_ratio" in terms:
        parts.append(f"min separation {terms['min_separation_ratio']:.2f}x required")
    parts.append(f"cost {float(alt.get('cost', 0.0)):.2f}, risk {float(alt.get('risk', 0.0)):.2f}")
    # the human part of the detail (before the scoring terms), if any
    label = detail.split(";", maxsplit=1)[0].strip()
    if label and not _TERM.search(label):
        parts.append(label)
    return ", ".join(parts)


def _utc(t_s: float) -> str:
    return datetime.datetime.fromtimestamp(t_s, datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def option_text(alt: dict[str, Any], *, details: bool = False) -> str:
    """One option in the pilot's words (the ``text`` gcs-utm sends with it; an older
    gcs-utm without it: :func:`option_summary`), ``details``: with the raw scores."""
    text = str(alt.get("text") or "")
    if not text:
        return option_summary(alt)
    return f"{text} [{option_summary(alt)}]" if details else text


def recommendation_text(rec: dict[str, Any], *, details: bool = False) -> str:
    """The lines shown for one recommendation (``details``: with the raw scores)."""
    created_s = float(rec.get("created_t_s", 0.0))
    deadline_s = float(rec.get("deadline_t_s", 0.0))
    lines = [
        f"recommendation {rec.get('recommendation_id')} v{rec.get('version')} "
        f"for UAS {rec.get('operation_id')}: {_words(rec.get('threat_kind'))} "
        f"(threat {rec.get('threat_id')})"
    ]
    if rec.get("why"):
        lines.append(f"  why: {rec['why']}")
    if rec.get("reason") and (details or not rec.get("why")):
        lines.append(f"  reason: {rec['reason']}")
    command = rec.get("command")
    if isinstance(command, dict):
        lines.append(f"  command: {command.get('text') or command.get('kind')}")
    opts = options(rec)
    for row, alt in enumerate(opts):
        proposed = " (proposed)" if row == 0 and isinstance(rec.get("selected"), dict) else ""
        lines.append(f"  [{row}] {option_text(alt, details=details)}{proposed}")
    if not opts:
        lines.append("  (no alternative flight plan)")
    lines.append(
        f"  deadline {_utc(deadline_s)} ({deadline_s - created_s:.0f} s after it was issued)"
    )
    lines.append(f"  {HELP}")
    return "\n".join(lines)


def ack_text(outcome: str, state: str | None, reason: str, rec_id: str, version: int) -> str:
    """gcs-utm's acknowledgement of an answer."""
    what = f"recommendation {rec_id} v{version}"
    if outcome == "accepted":
        return f"gcs-utm accepted the answer to {what} (state {state})"
    if outcome == "duplicate":
        return f"gcs-utm already had this answer to {what} (duplicate; state {state})"
    return f"gcs-utm refused the answer to {what}: {reason or outcome}"


def status_text(status: dict[str, Any]) -> str:
    """A state change of a recommendation (expired, superseded, applied, ...)."""
    what = f"recommendation {status.get('recommendation_id')} v{status.get('version')}"
    state = status.get("state")
    reason = status.get("reason") or ""
    tail = f": {reason}" if reason else ""
    if state == "expired":
        return f"!!! EXPIRED {what}: nobody answered in time - no longer answerable{tail}"
    if state == "superseded":
        return f"{what} {state} - no longer answerable{tail}"
    return f"{what} is now {state}{tail}"


__all__ = [
    "HELP",
    "Choice",
    "ack_text",
    "alternative_index",
    "option_summary",
    "option_text",
    "options",
    "parse_choice",
    "recommendation_text",
    "status_text",
]
