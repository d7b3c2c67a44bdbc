"""A recommendation nobody answers (``[emergency] expiry_action``): by default the safe
command is proposed again as a new version, each time it expires, and the audit says what
followed; ``replan`` keeps the re-plan without the expired manoeuvre."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.emergency import EmergencyConfig
from gcs_utm.model import RecommendationState

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_em import at, make_em


def test_expiry_proposes_the_safe_command_again_and_keeps_asking() -> None:
    snap, threat = sc.scenario_los_2uas()
    em = make_em()
    rec = em.on_threat(threat, snap).recommendations[0]
    assert rec.selected is not None  # a plan was proposed first
    d = em.on_expired(rec, at(snap, rec.deadline_t_s + 1.0))
    assert [r.state for r in d.recommendations if r.version == rec.version] == [
        RecommendationState.EXPIRED
    ]
    (again,) = [r for r in em.pending() if r.id == rec.id]
    assert again.version == rec.version + 1
    assert again.command is not None and again.selected is None  # the safe command first
    assert "expired without an answer" in again.reason
    (audit,) = [a for a in d.audit if a.action == "expired"]
    assert audit.detail["expiry_action"] == "repropose"
    assert audit.detail["next"].startswith(f"v{again.version} ")
    assert audit.detail["next"].endswith(" proposed")
    # nobody answers the command either: it is proposed again, never dropped
    d2 = em.on_expired(again, at(snap, again.deadline_t_s + 1.0))
    (third,) = [r for r in em.pending() if r.id == rec.id]
    assert third.version == again.version + 1 and third.command is not None
    assert d2.escalations and "expired" in d2.escalations[0]


def test_replan_on_expiry_is_a_choice() -> None:
    snap, threat = sc.scenario_geofence_reroute(20)
    em = make_em(expiry_action="replan")
    rec = em.on_threat(threat, snap).recommendations[0]
    assert rec.selected is not None
    d = em.on_expired(rec, at(snap, rec.deadline_t_s + 1.0))
    (again,) = em.pending()
    assert again.selected is not None and again.command is None  # a new plan
    assert again.selected.maneuver is not rec.selected.maneuver
    (audit,) = [a for a in d.audit if a.action == "expired"]
    assert audit.detail["expiry_action"] == "replan"


def test_an_unknown_expiry_action_is_refused() -> None:
    with pytest.raises(ValueError, match=r"emergency\.expiry_action"):
        EmergencyConfig(expiry_action="execute")
