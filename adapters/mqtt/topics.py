"""Topic layout of the MQTT interface (see :mod:`adapters.mqtt.codec` for the table): topic
names under one prefix, and the classification of an inbound topic into its kind and
operator. An operator name is a topic level and a broker user name, so the broker ACL can
bind topics to identities."""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import Enum

from adapters.mqtt.wire import MqttMessageError

_OPERATOR_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


class InboundKind(Enum):
    RPA_STATE = "rpa_state"
    FLIGHT_PLAN = "flight_plan"
    FLIGHT_STATUS = "flight_status"
    PILOT_ANSWER = "pilot_answer"
    ADSB = "adsb"
    AIRSPACE_ALERT = "airspace_alert"
    OPERATOR_COMMAND = "operator_command"


OUTBOUND_OPERATOR_LEAVES = frozenset({"alerts", "recommendations", "status", "errors"})
"""Leaves the UTM itself publishes under ``operators/<op>/``: the ``operators/+/+``
subscription sees them come back, and they are ignored (never answered with an error, which
would loop)."""

_OPERATOR_SUFFIX = {
    "state": InboundKind.RPA_STATE,
    "flight_plans": InboundKind.FLIGHT_PLAN,
    "flight_status": InboundKind.FLIGHT_STATUS,
    "answers": InboundKind.PILOT_ANSWER,
    "commands": InboundKind.OPERATOR_COMMAND,
}


def valid_operator(name: str) -> bool:
    """Operator names are topic levels and broker user names: no ``/``, ``+``, ``#``."""
    return bool(_OPERATOR_RE.match(name))


@dataclass(frozen=True, slots=True)
class Topics:
    """The topic names under one prefix."""

    prefix: str = "gcs_utm"

    def operator(self, operator: str, leaf: str) -> str:
        if not valid_operator(operator):
            raise ValueError(f"operator name {operator!r} is not a valid topic level")
        return f"{self.prefix}/operators/{operator}/{leaf}"

    def state(self, operator: str) -> str:
        return self.operator(operator, "state")

    def flight_plans(self, operator: str) -> str:
        return self.operator(operator, "flight_plans")

    def flight_status(self, operator: str) -> str:
        return self.operator(operator, "flight_status")

    def answers(self, operator: str) -> str:
        return self.operator(operator, "answers")

    def commands(self, operator: str) -> str:
        return self.operator(operator, "commands")

    def alerts_for(self, operator: str) -> str:
        return self.operator(operator, "alerts")

    def recommendations(self, operator: str) -> str:
        return self.operator(operator, "recommendations")

    def status(self, operator: str) -> str:
        return self.operator(operator, "status")

    def errors_for(self, operator: str) -> str:
        return self.operator(operator, "errors")

    @property
    def adsb(self) -> str:
        return f"{self.prefix}/surveillance/adsb"

    @property
    def airspace_alerts(self) -> str:
        return f"{self.prefix}/authority/alerts"

    @property
    def alerts(self) -> str:
        return f"{self.prefix}/alerts"

    @property
    def geofences(self) -> str:
        return f"{self.prefix}/geofences"

    @property
    def geofence_events(self) -> str:
        return f"{self.prefix}/geofences/events"

    @property
    def traffic(self) -> str:
        return f"{self.prefix}/traffic"

    @property
    def errors(self) -> str:
        return f"{self.prefix}/errors"

    @property
    def bridge(self) -> str:
        return f"{self.prefix}/bridge"

    def subscriptions(self) -> tuple[str, ...]:
        """Topic filters the UTM subscribes to. ``operators/+/+`` (not only the four
        leaves) so a message on an unknown leaf gets an error instead of silence."""
        return (
            f"{self.prefix}/operators/+/+",
            f"{self.prefix}/surveillance/+",
            f"{self.prefix}/authority/+",
        )

    def is_own_output(self, topic: str) -> bool:
        """True for an operator topic the UTM publishes on (echo of its own output)."""
        parts = topic.split("/")
        return self.operator_of(topic) is not None and parts[-1] in OUTBOUND_OPERATOR_LEAVES

    def classify(self, topic: str) -> tuple[InboundKind, str | None]:
        """Map an inbound topic to its kind and operator (None for non-operator topics);
        raise :class:`MqttMessageError` for a topic that is not an inbound operation."""
        head = f"{self.prefix}/"
        if not topic.startswith(head):
            raise MqttMessageError(topic, "", "topic outside the gcs-utm prefix")
        parts = topic[len(head) :].split("/")
        if len(parts) == 3 and parts[0] == "operators":
            operator, leaf = parts[1], parts[2]
            if not valid_operator(operator):
                raise MqttMessageError(topic, "", f"invalid operator name {operator!r}")
            kind = _OPERATOR_SUFFIX.get(leaf)
            if kind is None:
                raise MqttMessageError(
                    topic,
                    "",
                    f"unknown operation {leaf!r}; expected one of {sorted(_OPERATOR_SUFFIX)}",
                )
            return kind, operator
        if topic == self.adsb:
            return InboundKind.ADSB, None
        if topic == self.airspace_alerts:
            return InboundKind.AIRSPACE_ALERT, None
        raise MqttMessageError(topic, "", "unknown operation (no inbound message on this topic)")

    def operator_of(self, topic: str) -> str | None:
        """The operator a topic belongs to, or None."""
        parts = topic.split("/")
        head = self.prefix.split("/")
        n = len(head)
        if len(parts) > n + 1 and parts[:n] == head and parts[n] == "operators":
            op = parts[n + 1]
            return op if valid_operator(op) else None
        return None
