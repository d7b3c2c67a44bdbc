"""Repeated escalations of the same thing are one escalation that is updated (issue 30): a
case retried every cycle raised the same escalation every 30 s (218 in 25 fence
encounters); now a repeat within ``emergency.escalation_window_s`` is a warning that updates
it, and something new (another UAS, cause or command) is still raised at once."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.clock import ManualClock
from gcs_utm.core.emergency import Decision
from gcs_utm.core.emergency.coalesce import EscalationCoalescer, escalation_key
from gcs_utm.services.emergency import EmergencyService

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import make_em

HOLD = "E1-T4-CONF: no feasible alternative for UAS2 (UAS_OUT_OV); {} proposed"
LATE = (
    "E1-T{}-LOS: loss predicted in {} s, sooner than a new plan can start (7.0 s: answer, "
    "upload, margin); immediate command does not keep (the best there is) the minima (ratio "
    "{}); operator action needed: hold for UAS2 proposed"
)


def _raised(c: EscalationCoalescer, text: str, t_s: float) -> bool:
    d = c.apply(Decision(escalations=(text,)), t_s)
    assert len(d.escalations) + len(d.warnings) == 1  # raised or updated, never lost
    return bool(d.escalations)


def test_a_repeat_within_the_window_updates_the_escalation_it_repeats() -> None:
    c = EscalationCoalescer(window_s=120.0)
    assert _raised(c, HOLD.format("hold"), 86.0)
    assert not _raised(c, HOLD.format("hold"), 98.0)
    d = c.apply(Decision(escalations=(HOLD.format("hold"),)), 128.0)
    assert d.escalations == ()
    assert d.warnings == (f"escalation update (2 since t=86.0): {HOLD.format('hold')}",)
    (audit,) = d.audit
    assert audit.action == "escalation_updated" and audit.subject == "E1-T4-CONF"
    assert audit.detail["repeats"] == 2
    # another threat id of the same pair, other times and ratios: the same escalation
    assert _raised(c, LATE.format(2, "5.4", "0.00"), 81.0)
    assert not _raised(c, LATE.format(6, "6.1", "0.30"), 95.0)
    # something new is raised at once: another UAS, another command
    assert _raised(c, HOLD.replace("UAS2", "UAS3").format("hold"), 99.0)
    assert _raised(c, HOLD.format("land"), 99.0)
    # after the window the persisting problem is raised again
    assert _raised(c, HOLD.format("hold"), 206.0)
    assert escalation_key(LATE.format(2, "5.4", "0.00")) == escalation_key(
        LATE.format(16, "-1.0", "1.25")
    )


def test_no_window_raises_every_escalation() -> None:
    c = EscalationCoalescer(window_s=0.0)
    assert all(_raised(c, HOLD.format("hold"), t) for t in (1.0, 1.0, 2.0))
    with pytest.raises(ValueError, match="escalation window"):
        EscalationCoalescer(window_s=float("nan"))


def test_the_emergency_service_hands_on_repeats_as_updates() -> None:
    """Through the service (every Decision passes it): the second identical escalation 30 s
    later reaches the USM as a warning, its recommendations unchanged."""
    clock = ManualClock(100.0)
    seen: list[Decision] = []

    async def on_decision(d: Decision) -> None:
        seen.append(d)

    svc = EmergencyService(make_em(), lambda t: sc.snapshot([]), clock, on_decision)
    esc = Decision(escalations=(HOLD.format("hold"),))
    asyncio.run(svc._decide(lambda: esc, "t"))  # the one path every step takes
    clock.advance(30.0)
    asyncio.run(svc._decide(lambda: esc, "t"))
    assert [d.escalations for d in seen] == [(HOLD.format("hold"),), ()]
    assert seen[1].warnings and seen[1].warnings[0].startswith("escalation update (1 since")
