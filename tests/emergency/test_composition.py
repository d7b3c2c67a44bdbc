"""EM as an orchestrator over parts (docs/emergency.md, "How EM is composed"): every policy
action has a part, and the Enums keep the names the TOML, the audit and the docs use."""

from __future__ import annotations

from gcs_utm.core.emergency import ACTIONS, DEFAULT_POLICY, EmergencyConfig
from gcs_utm.core.emergency import manager as em_manager
from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.decision import ONE_SHOT, SINGLE_MANEUVERS
from gcs_utm.model import ThreatKind


def test_every_action_is_dispatched_to_exactly_one_part() -> None:
    per_case = {Action.ALTERNATIVE_PLANS, *em_manager._WHOLE_CASE}
    per_uas = {Action.VERTICAL_AVOIDANCE, *SINGLE_MANEUVERS}
    assert not per_case & per_uas
    assert per_case | per_uas == set(Action)
    assert set(em_manager._WHOLE_CASE) == ONE_SHOT  # done once: warnings and geofences


def test_the_action_names_are_the_policy_names() -> None:
    assert ACTIONS == (
        "alternative_plans",
        "reroute",
        "back_to_plan",
        "warn",
        "suspend_and_geofence",
        "land_or_home",
        "alert_and_geofence",
        "geofence_from_area",
        "vertical_avoidance",
    )
    cfg = EmergencyConfig(policy={"INTRUDER": "warn"})
    assert cfg.action_for(ThreatKind.INTRUDER) is Action.WARN
    for kind in ThreatKind:
        got = EmergencyConfig().action_for(kind)
        assert isinstance(got, Action) and got == DEFAULT_POLICY[kind.value]
