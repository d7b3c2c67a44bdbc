"""A supervised case is decided again before the loss it still predicts, not ``retry_after_s``
after its last attempt (``core/emergency/supervision_due.py``).

``enc_6_0475_endpoint_crossing``: a multirotor's new plan round a fixed wing circling its end
point was decided at 129 s for a loss predicted at 158.5 s; the threat stayed predicted, and
the next look came 30 s later, at 159 s, inside the loss (39.9 m against 50 m)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.emergency import Decision
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.emergency.supervision_due import retry_wait_s
from gcs_utm.model import RecommendationState, ThreatKind, ThreatStatus
from tests.emergency.test_supervision import accept_all, at, make_em


@pytest.mark.parametrize(
    ("event_in_s", "expected_s"),
    [(None, 30.0), (300.0, 30.0), (40.0, 40.0 - 7.0 - 15.0), (20.0, 10.0)],
    ids=["no-event", "far", "sooner-than-the-retry", "nearer-than-the-grace"],
)
def test_the_wait_ends_a_new_plan_s_lead_and_margins_before_the_event(
    event_in_s: float | None, expected_s: float
) -> None:
    """The wait leaves a new plan's lead (a pilot's answer up to the deadline, the upload,
    a margin: 7 s for a loss 40 s ahead) plus the immediate margin (5 s) and the grace (10 s)
    before the event, never less than the grace, never more than ``retry_after_s`` (30 s)."""
    _snap, threat = sc.scenario_los_2uas()
    em = make_em()
    event = None if event_in_s is None else sc.T0_S + event_in_s
    case = Case(
        threat=replace(threat, predicted_event_at_s=event),
        action=em.config.action_for(threat.kind),
        attempt_t_s=sc.T0_S,
    )
    if event is not None and event_in_s == 40.0:
        assert em.plan_start(case.threat, sc.T0_S) == pytest.approx(sc.T0_S + 7.0)
    assert retry_wait_s(em.ctx, case, sc.T0_S) == pytest.approx(expected_s)


def test_a_loss_still_predicted_is_decided_again_before_it_begins() -> None:
    """After a supervision's new decision the case used to wait ``retry_after_s`` (30 s)
    whatever the threat predicted: a loss 40 s after that attempt was next looked at 30 s
    on, with 10 s left (a new plan's lead plus the immediate margin are 12 s). Now it is
    decided again 18 s on, the commands of that decision settled."""
    snap, threat = sc.scenario_los_2uas()
    threat = replace(threat, predicted_event_at_s=sc.T0_S + 300.0)
    em = make_em(max_replans=5)
    (acc,) = accept_all(em, em.on_threat(threat, snap), at(snap, 1.0))
    due = em.supervision_due(acc)
    assert due is not None
    t_a = due - sc.T0_S + 0.5  # the first supervision: a new decision
    updated = replace(threat, status=ThreatStatus.UPDATED, updated_at_s=sc.T0_S + t_a)
    d = em.on_threat(updated, at(snap, t_a))
    assert any(a.action == "supervision" for a in d.audit)
    accepted = accept_all(em, d, at(snap, t_a + 0.5))
    assert accepted and all(r.state is RecommendationState.ACCEPTED for r in accepted)
    # the loss is still predicted, now 40 s after that attempt
    soon = replace(updated, predicted_event_at_s=sc.T0_S + t_a + 40.0)
    # a new plan's lead is 7 s for it: the wait is 40 - 7 - 5 - 10 = 18 s
    assert em.on_threat(soon, at(snap, t_a + 17.5)) == Decision()  # within the wait
    d2 = em.on_threat(soon, at(snap, t_a + 18.5))  # 21.5 s before the loss
    assert any(a.action == "supervision" for a in d2.audit)
    assert d2.recommendations or d2.escalations


def test_a_threat_whose_event_no_plan_moves_waits_the_full_retry() -> None:
    """LACK_OF_BATTERY's predicted event (the reserve) is not moved by a new plan: its case
    waits ``retry_after_s`` (a return_home was re-uploaded every 14 s and replaced by a LAND
    before the UAS had landed, tests/e2e/test_ground_rules_sitl.py)."""
    _snap, threat = sc.scenario_los_2uas()
    em = make_em()
    battery = replace(threat, kind=ThreatKind.LACK_OF_BATTERY, predicted_event_at_s=sc.T0_S + 40.0)
    case = Case(threat=battery, action=em.config.action_for(battery.kind), attempt_t_s=sc.T0_S)
    assert retry_wait_s(em.ctx, case, sc.T0_S) == pytest.approx(em.config.retry_after_s)
