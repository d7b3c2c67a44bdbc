"""What the MQTT side tells a pilot about an answer (published on the pilot's status topic by
:meth:`adapters.mqtt.bridge.MqttBridge.publish_answer_outcome`).

The USM decides what an answer means (:meth:`gcs_utm.services.usm.Usm.answer`, rules in
:mod:`gcs_utm.services.recommendations`); :class:`AnswerOutcome` carries its decision, with
the recommendation's state after it, back to the pilot. ``AnswerStatus.ACCEPTED`` means *the
answer was taken*; the recommendation itself then goes to ``accepted`` or ``rejected`` as the
pilot decided (``AnswerOutcome.state``).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from gcs_utm.messages import PilotDecision
from gcs_utm.model import RecommendationId, RecommendationState


class AnswerStatus(Enum):
    ACCEPTED = "accepted"
    DUPLICATE = "duplicate"
    REFUSED = "refused"


@dataclass(frozen=True, slots=True, kw_only=True)
class AnswerOutcome:
    """What became of one pilot answer. ``state`` is the recommendation state after it (None
    when the recommendation is unknown)."""

    status: AnswerStatus
    recommendation_id: RecommendationId
    version: int
    decision: PilotDecision
    reason: str = ""
    state: RecommendationState | None = None
