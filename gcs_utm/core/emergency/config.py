"""Settings of Emergency Management (section ``[emergency]``).

``policy`` maps a :class:`gcs_utm.model.ThreatKind` name to an action (one of
:class:`Action`); the table and what each action does are in ``docs/emergency.md``. ``alpha``
weighs cost and ``beta`` riskiness in the joint selection ``min sum(alpha*c + beta*r)`` (paper
eq. 1); safety is favoured by default (beta > alpha).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from gcs_utm.config import setting
from gcs_utm.model import ThreatKind


class Action(StrEnum):
    """What EM does about a threat kind (``[emergency] policy``). The values are the names
    in the TOML, the audit and the docs."""

    ALTERNATIVE_PLANS = "alternative_plans"  # multi-UAS charged cords + joint selection
    REROUTE = "reroute"  # single-UAS A*: reroute, escape, direct to goal, back to plan, ...
    BACK_TO_PLAN = "back_to_plan"  # back to the closest plan point or the next waypoint
    WARN = "warn"  # operator warning only
    SUSPEND_AND_GEOFENCE = "suspend_and_geofence"  # hold/land it, geofence around it
    LAND_OR_HOME = "land_or_home"  # nearest reachable landing site or home; land now if none
    ALERT_AND_GEOFENCE = "alert_and_geofence"  # alert, geofence around the predicted position
    GEOFENCE_FROM_AREA = "geofence_from_area"  # the alert's area becomes a geofence
    VERTICAL_AVOIDANCE = "vertical_avoidance"  # climb or descend away from an intruder


ACTIONS = tuple(a.value for a in Action)
"""The action names a policy may use."""


class ExpiryAction(StrEnum):
    """What EM does with a recommendation nobody answered in time (``expiry_action``)."""

    REPROPOSE = "repropose"  # the safe command proposed again, as a new version
    REPLAN = "replan"  # a new plan without the expired manoeuvre


EXPIRY_ACTIONS = tuple(a.value for a in ExpiryAction)

DEFAULT_POLICY: dict[str, str] = {
    ThreatKind.LOSS_OF_SEPARATION.value: "alternative_plans",
    ThreatKind.GEOFENCE_CONFLICT.value: "reroute",
    ThreatKind.GEOFENCE_INTRUSION.value: "reroute",
    ThreatKind.UAS_OUT_OV.value: "back_to_plan",
    ThreatKind.UAS_IN_CV.value: "warn",
    ThreatKind.JAMMING_ATTACK.value: "suspend_and_geofence",
    ThreatKind.SPOOFING_ATTACK.value: "suspend_and_geofence",
    # the impostor's frames are dropped at the link: the bound vehicle flies on, the operator
    # is told (holding a healthy vehicle because another sender shares its sysid helps nobody)
    ThreatKind.SYSID_CONFLICT.value: "warn",
    ThreatKind.GNSS_DEGRADATION.value: "land_or_home",
    ThreatKind.LACK_OF_BATTERY.value: "land_or_home",
    ThreatKind.TECHNICAL_FAILURE.value: "land_or_home",
    ThreatKind.COMMUNICATION_FAILURE.value: "alert_and_geofence",
    ThreatKind.ALERT_WARNING.value: "geofence_from_area",
    ThreatKind.INTRUDER.value: "vertical_avoidance",
    ThreatKind.REMOTE_ID_MISMATCH.value: "warn",  # the broadcast is wrong, not the flight
}


@dataclass(frozen=True, slots=True, kw_only=True)
class EmergencyConfig:
    alpha: float = setting(1.0, "weight of cost in the joint selection (paper eq. 1)", min=0.0)
    beta: float = setting(
        3.0, "weight of riskiness in the joint selection; > alpha favours safety", min=0.0
    )
    # setting() turns a dict default into a default_factory copy, so this is not shared state.
    policy: dict[str, str] = setting(
        DEFAULT_POLICY, "action per threat kind (see docs/emergency.md for the actions)"
    )
    autonomous: bool = setting(
        False, "apply decisions without operator confirmation (recommendations born accepted)"
    )
    max_combinations: int = setting(
        20000,
        "joint selection explores at most this many partial combinations (branch and bound); "
        "when exceeded the best found so far is used and the audit says so",
        min=1,
    )
    deadline_margin_s: float = setting(
        10.0,
        "a recommendation's deadline is the predicted event time minus this",
        min=0.0,
        unit="s",
    )
    min_response_s: float = setting(
        15.0, "the shortest time an operator is given to answer", min=0.0, unit="s"
    )
    answer_window_s: float = setting(
        20.0,
        "a recommendation's deadline is at most this long after the decision (never less "
        "than min_response_s): the plan it carries starts after it, so it must come early "
        "enough for the plan to resolve the threat",
        min=0.0,
        unit="s",
    )
    expected_answer_s: float = setting(
        2.0,
        "time the operator is expected to take to answer (never more than up to the "
        "deadline); a plan starts after it plus upload_time_s and start_margin_s, and carries "
        "the current path before that (an earlier answer); a later answer joins the plan at "
        "its first waypoint still ahead in time. At least answer_window_s: plan for an answer "
        "at the deadline. An automatic operator's delay replaces it (the default equals "
        "dashboard.auto_answer_delay_s)",
        min=0.0,
        unit="s",
    )
    upload_time_s: float = setting(
        3.0,
        "time expected from an accepted answer to a verified mission on the vehicle",
        min=0.0,
        unit="s",
    )
    start_margin_s: float = setting(
        2.0,
        "a new plan starts this long after the expected answer and upload: the vehicle has "
        "it before it reaches the plan's first waypoint (ahead of it on its path)",
        min=0.0,
        unit="s",
    )
    immediate_margin_s: float = setting(
        5.0,
        "a loss predicted less than a new plan's lead (answer, upload, start_margin_s) plus "
        "this far ahead gets the immediate command (hold, climb or descend in place) instead "
        "of new plans whenever that command keeps the minima: a plan that starts just before "
        "the event leaves no room for the vehicles' tracking error",
        min=0.0,
        unit="s",
    )
    supervision_grace_s: float = setting(
        10.0,
        "a threat still open this long after its accepted plan started (and was uploaded) "
        "gets a new recommendation version, or an escalation after max_replans",
        min=1.0,
        unit="s",
    )
    default_event_horizon_s: float = setting(
        60.0, "assumed time to the event when a threat does not predict one", min=1.0, unit="s"
    )
    max_replans: int = setting(
        3, "re-plans per threat and UAS after rejection or expiry before escalating", min=0
    )
    retry_after_s: float = setting(
        30.0,
        "a persisting threat whose handling ended in escalation is re-planned this often",
        min=1.0,
        unit="s",
    )
    escalation_window_s: float = setting(
        120.0,
        "an escalation that repeats an earlier one (the same UAS, cause and proposed command; "
        "threat ids and numbers aside) within this long after it is not raised again: it "
        "updates the earlier one (a warning and an escalation_updated audit entry). 0: every "
        "escalation is raised",
        min=0.0,
        unit="s",
    )
    expiry_action: str = setting(
        "repropose",
        "what EM does when a recommendation expires without an answer: 'repropose' (the "
        "safe command proposed again as a new version, every time it expires: the operator "
        "keeps being asked, nothing is carried out unanswered) or 'replan' (a new plan "
        "without the expired manoeuvre, the safe command after max_replans)",
    )
    suspend_command: str = setting(
        "hold", "command for a suspended operation (jamming/spoofing): 'hold' or 'land'"
    )
    jamming_radius_m: float = setting(
        50.0,
        "radius of the dynamic geofence around a jammed/spoofed UAS (its position is "
        "unreliable; the paper's use case 2)",
        min=1.0,
        unit="m",
    )
    jamming_band_m: float = setting(
        150.0, "half height of that geofence around the UAS altitude", min=1.0, unit="m"
    )
    jamming_duration_s: float = setting(
        1800.0, "how long that geofence stays active", min=1.0, unit="s"
    )
    link_loss_radius_m: float = setting(
        200.0,
        "radius of the temporary geofence around a lost UAS's predicted position",
        min=1.0,
        unit="m",
    )
    link_loss_band_m: float = setting(
        100.0, "half height of the link-loss geofence", min=1.0, unit="m"
    )
    link_loss_duration_s: float = setting(
        600.0, "how long the link-loss geofence stays active", min=1.0, unit="s"
    )
    link_loss_predict_s: float = setting(
        10.0,
        "the lost UAS's position is taken from its plan this far after the loss",
        min=0.0,
        unit="s",
    )
    alert_duration_s: float = setting(
        3600.0,
        "duration of a geofence from an alert area without its own end time",
        min=1.0,
        unit="s",
    )

    def __post_init__(self) -> None:
        for kind, action in self.policy.items():
            if kind not in ThreatKind.__members__:
                raise ValueError(f"emergency.policy: unknown threat kind {kind!r}")
            if action not in ACTIONS:
                raise ValueError(
                    f"emergency.policy.{kind}: expected one of {ACTIONS}, got {action!r}"
                )
        if self.expiry_action not in EXPIRY_ACTIONS:
            raise ValueError(
                f"emergency.expiry_action: expected one of {EXPIRY_ACTIONS}, got "
                f"{self.expiry_action!r}"
            )
        if self.suspend_command not in ("hold", "land"):
            raise ValueError(
                f"emergency.suspend_command: expected 'hold' or 'land', got "
                f"{self.suspend_command!r}"
            )

    def action_for(self, kind: ThreatKind) -> Action:
        return Action(self.policy.get(kind.value, DEFAULT_POLICY[kind.value]))
