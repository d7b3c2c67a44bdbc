"""How long a supervised case waits before it is decided again: ``retry_after_s``, but never
past the event it still predicts.

A case whose accepted plans are settled while Monitoring still predicts its loss is decided
again (:mod:`.supervision`), then waits ``retry_after_s`` (30 s) before the next attempt, so
that a threat that persists does not get a new plan every cycle. When the loss it predicts
comes sooner than that, the wait runs past it: the case is looked at again only once the
loss has begun, and the new decision can do no more than propose a hold. A multirotor sent
round a fixed wing circling its end point (its phase predicted ahead of the aircraft) was
decided again at 129 s for a loss at 158.5 s, still predicted after the new plan, and next
at 159 s, 0.3 s into the loss (``enc_6_0475_endpoint_crossing``, 39.9 m against 50 m).

So the wait ends, at the latest, when a new plan decided then still starts
``immediate_margin_s`` plus ``supervision_grace_s`` before the predicted event (a plan
decided later is the immediate command's business, :mod:`.immediate`), and never sooner than
``supervision_grace_s`` after the last attempt (a plan decided at that attempt has not shown
its effect before that). Only for a separation the plans can still keep (a loss of
separation, an intruder): the event of another threat (a battery's reserve, a link) is not
moved by a new plan, and deciding it again sooner only re-plans the same answer (a
return_home under LACK_OF_BATTERY was re-uploaded every 14 s and replaced by a LAND before it
had landed). Pure.
"""

from __future__ import annotations

from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case
from gcs_utm.model import ThreatKind

SEPARATION_KINDS = frozenset({ThreatKind.LOSS_OF_SEPARATION, ThreatKind.INTRUDER})
"""The threats whose predicted event a new plan can still avoid: supervised before it."""


def retry_wait_s(em: EmContext, case: Case, now: float) -> float:
    """Seconds after ``case.attempt_t_s`` before ``case`` is supervised again (see the module
    doc): ``retry_after_s``, shortened to the last moment that leaves a new plan its lead plus
    ``immediate_margin_s`` and ``supervision_grace_s`` before the threat's predicted event,
    but at least ``supervision_grace_s``."""
    cfg = em.config
    event = case.threat.predicted_event_at_s
    if event is None or case.threat.kind not in SEPARATION_KINDS:
        return cfg.retry_after_s
    lead_s = em.plan_start(case.threat, now) - now
    latest = event - lead_s - cfg.immediate_margin_s - cfg.supervision_grace_s
    return min(cfg.retry_after_s, max(cfg.supervision_grace_s, latest - case.attempt_t_s))
