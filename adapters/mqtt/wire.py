"""The MQTT interface's wire rules: schema version, message types, the one error type,
strict JSON parsing and writing, and validation against the packaged JSON Schemas
(``adapters/mqtt/schemas/<type>.json``, draft 2020-12).

Every incoming payload is parsed as strict JSON (no NaN/Infinity, bounded size and nesting)
and validated against its schema; any failure is one :class:`MqttMessageError` naming the
topic, the field (a dotted path) and the reason. Outgoing JSON is written with
``allow_nan=False`` so it is always valid JSON.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from functools import cache
from importlib import resources
from typing import Any

import jsonschema
from referencing import Registry, Resource

from gcs_utm.validation import nesting_problem, too_deep

SCHEMA_VERSION = 1
MAX_PAYLOAD_BYTES = 1_048_576
"""Larger payloads are refused before parsing: the largest legitimate message (a flight plan
of 10,000 waypoints) is about 800 kB."""

INBOUND_TYPES = (
    "rpa_state",
    "adsb",
    "flight_status",
    "flight_plan",
    "pilot_answer",
    "airspace_alert",
    "operator_command",
)
OUTBOUND_TYPES = (
    "alert",
    "recommendation",
    "recommendation_status",
    "geofences",
    "geofence_event",
    "traffic",
    "error",
    "bridge_status",
    "command_status",
)
MESSAGE_TYPES = INBOUND_TYPES + OUTBOUND_TYPES


class MqttMessageError(ValueError):
    """A message that cannot be accepted: ``topic`` it came on, ``field`` (dotted path, ``""``
    for the whole message) and ``reason``."""

    def __init__(self, topic: str, field: str, reason: str) -> None:
        super().__init__(f"{topic}: {field or '<message>'}: {reason}")
        self.topic = topic
        self.field = field
        self.reason = reason


@cache
def _registry() -> tuple[Registry[Any], dict[str, dict[str, Any]]]:
    folder = resources.files("adapters.mqtt") / "schemas"
    schemas: dict[str, dict[str, Any]] = {}
    resources_: list[tuple[str, Resource[Any]]] = []
    for name in ("common", *MESSAGE_TYPES):
        contents = json.loads((folder / f"{name}.json").read_text(encoding="utf-8"))
        schemas[name] = contents
        resources_.append((contents["$id"], Resource.from_contents(contents)))
    registry: Registry[Any] = Registry().with_resources(resources_)
    return registry, schemas


@cache
def _validator(message_type: str) -> Any:
    registry, schemas = _registry()
    schema = schemas[message_type]
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema, registry=registry, format_checker=cls.FORMAT_CHECKER)


def schema(message_type: str) -> dict[str, Any]:
    """The JSON Schema of ``message_type`` (a copy of the packaged file's contents)."""
    if message_type not in MESSAGE_TYPES:
        raise KeyError(message_type)
    return json.loads(json.dumps(_registry()[1][message_type]))  # type: ignore[no-any-return]


def _path(error: Any) -> str:
    return ".".join(str(p) for p in error.absolute_path)


def validate(message_type: str, obj: object, topic: str = "") -> None:
    """Raise :class:`MqttMessageError` when ``obj`` violates the schema of ``message_type``.
    The reported error is the most specific one (``jsonschema.exceptions.best_match``)."""
    validator = _validator(message_type)
    error = jsonschema.exceptions.best_match(validator.iter_errors(obj))
    if error is None:
        return
    # best_match may descend into the wrong oneOf branch: go back to the top error and take
    # the branch that was meant (the one whose "shape"-like const matched), e.g. report a
    # circle without a radius rather than "'polygon' was expected"
    while error.parent is not None:
        error = error.parent
    while error.context:
        branches: dict[object, list[Any]] = {}
        for e in error.context:
            branches.setdefault(e.relative_schema_path[0], []).append(e)
        meant = [b for b in branches.values() if not any(e.validator == "const" for e in b)]
        pool = meant[0] if len(meant) == 1 else list(error.context)
        error = max(pool, key=lambda e: len(e.absolute_path))
    field = _path(error)
    if error.validator == "required" and isinstance(error.instance, dict):
        missing = [k for k in error.validator_value if k not in error.instance]
        if missing:
            field = f"{field}.{missing[0]}" if field else str(missing[0])
    raise MqttMessageError(topic, field, short(error.message))


def short(text: str, limit: int = 200) -> str:
    """``text`` cut to ``limit`` characters (an ellipsis marks the cut)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not valid JSON")


def parse_json(topic: str, payload: bytes | bytearray | str) -> object:
    """Strict JSON: UTF-8, no NaN/Infinity, at most :data:`MAX_PAYLOAD_BYTES`, nested at most
    :data:`gcs_utm.validation.MAX_NESTING` levels (the rule of every input)."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MqttMessageError(
            topic, "", f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}"
        )
    try:
        text = payload if isinstance(payload, str) else bytes(payload).decode("utf-8")
        obj = json.loads(text, parse_constant=_reject_constant)
    except UnicodeDecodeError as exc:
        raise MqttMessageError(topic, "", f"payload is not UTF-8: {exc.reason}") from exc
    except RecursionError:
        raise MqttMessageError(topic, "", f"malformed JSON: {too_deep()}") from None
    except ValueError as exc:  # json.JSONDecodeError and the NaN rejection
        raise MqttMessageError(topic, "", f"malformed JSON: {short(str(exc))}") from exc
    problem = nesting_problem(obj)
    if problem is not None:
        raise MqttMessageError(topic, "", f"malformed JSON: {problem}")
    return obj


def dumps(obj: Mapping[str, object]) -> bytes:
    """Compact, valid JSON (raises ValueError on NaN/inf rather than emitting non-JSON)."""
    return json.dumps(obj, allow_nan=False, separators=(",", ":"), sort_keys=False).encode()
