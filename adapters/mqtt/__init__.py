"""MQTT door of the U-space Service Manager: JSON messages over an MQTT broker (paper §5.2).

- :mod:`adapters.mqtt.codec`: sans-IO JSON <-> typed messages, validated by the JSON Schemas in
  ``adapters/mqtt/schemas``; topic layout. It decodes and re-exports :mod:`.wire` (strict
  JSON, schemas, the error type), :mod:`.topics` (topic names) and :mod:`.encode` (outbound).
- :mod:`adapters.mqtt.answers`: the outcome of a pilot's answer as published back to the
  pilot (the USM decides it: :mod:`gcs_utm.services.recommendations`).
- :mod:`adapters.mqtt.bridge`: the aiomqtt client with reconnect, bounded outgoing queue and
  error reporting.
"""
