"""Sans-IO tests: schema errors, queue policy."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mqtt_helpers import T0

from adapters.mqtt.bridge import MqttBridge
from adapters.mqtt.codec import MqttMessageError, Topics, decode, validate
from adapters.mqtt.config import MqttConfig
from gcs_utm.clock import ManualClock
from gcs_utm.messages import HazardReport
from gcs_utm.model import (
    OperationId,
    ThreatId,
    ThreatKind,
)

T = Topics()


def test_schema_errors_name_the_field() -> None:
    good = {
        "schema_version": 1,
        "type": "pilot_answer",
        "recommendation_id": "r",
        "version": 1,
        "decision": "accept",
        "t_s": 1.0,
    }
    cases = {
        "decision": {**good, "decision": "maybe"},
        "version": {**good, "version": "1"},
        "extra": {**good, "extra": 1},
        "t_s": {k: v for k, v in good.items() if k != "t_s"},
    }
    for field, obj in cases.items():
        with pytest.raises(MqttMessageError) as err:
            decode(T, T.answers("alice"), json.dumps(obj), 0.0)
        assert err.value.field == field or field == "extra", (field, err.value)
        assert err.value.topic == T.answers("alice")
    with pytest.raises(MqttMessageError, match="unknown operation"):
        T.classify("gcs_utm/operators/alice/launch")
    with pytest.raises(MqttMessageError, match="NaN"):
        decode(T, T.answers("alice"), b'{"t_s": NaN}', 0.0)
    with pytest.raises(MqttMessageError, match="'adsb' message on a 'pilot_answer' topic"):
        decode(T, T.answers("alice"), json.dumps({**good, "type": "adsb"}), 0.0)
    validate("pilot_answer", good)


def test_outgoing_queue_is_bounded_latest_wins_and_backoff_capped() -> None:
    clock = ManualClock(T0)
    cfg = MqttConfig(queue_max=5, backoff_initial_s=0.5, backoff_max_s=4.0, traffic_rate_hz=1.0)
    bridge = MqttBridge(cfg, clock, handler=None)  # type: ignore[arg-type]
    for i in range(8):
        bridge.publish_error(f"gcs_utm/x/{i}", "", "bad")
    assert bridge.pending == 5 and bridge.stats.dropped == 3
    bridge.publish_geofences([])
    bridge.publish_geofences([])  # latest-wins: still one retained state message queued
    assert bridge.pending == 5 and bridge.stats.dropped == 4
    assert bridge.publish_traffic([]) and not bridge.publish_traffic([])
    clock.advance(1.0)
    assert bridge.publish_traffic([])
    for n in range(1, 12):
        d = bridge.backoff_s(n)
        ceiling = min(4.0, 0.5 * 2 ** (n - 1))
        assert ceiling / 2 <= d <= ceiling


def _alert(geometry: dict[str, object], **over: object) -> bytes:
    obj: dict[str, object] = {
        "schema_version": 1,
        "type": "airspace_alert",
        "alert_id": "fire-1",
        "category": "wildfire",
        "t_s": T0,
        "min_alt_amsl_m": 0.0,
        "max_alt_amsl_m": 3000.0,
        "geometry": geometry,
        **over,
    }
    return json.dumps(obj).encode()


def _ring(*lat_lon: tuple[float, float]) -> dict[str, object]:
    return {
        "shape": "polygon",
        "vertices": [{"lat_deg": a, "lon_deg": b} for a, b in lat_lon],
    }


def test_alert_polygons_follow_the_shared_rule() -> None:
    """An alert with a bow-tie polygon creates no geofence: the same rule as scenario files
    (gcs_utm.validation.polygon_problem) refuses it, naming the field."""
    square = ((40.40, -3.70), (40.41, -3.70), (40.41, -3.69), (40.40, -3.69))
    h = decode(T, T.airspace_alerts, _alert(_ring(*square)), T0)
    assert isinstance(h, HazardReport) and h.area is not None and len(h.area.vertices) == 4
    bow_tie = (square[0], square[2], square[1], square[3])
    with pytest.raises(MqttMessageError) as err:
        decode(T, T.airspace_alerts, _alert(_ring(*bow_tie)), T0)
    assert err.value.field == "geometry.vertices" and "intersects itself" in err.value.reason
    with pytest.raises(MqttMessageError, match="no area"):
        decode(T, T.airspace_alerts, _alert(_ring((40.4, -3.7), (40.5, -3.7), (40.6, -3.7))), T0)
    circle = {"shape": "circle", "center": {"lat_deg": 40.4, "lon_deg": -3.7}, "radius_m": 1e9}
    with pytest.raises(MqttMessageError) as err:
        decode(T, T.airspace_alerts, _alert(circle), T0)
    assert err.value.field == "geometry.radius_m"
    with pytest.raises(MqttMessageError) as err:
        decode(T, T.airspace_alerts, _alert(_ring(*square), max_alt_amsl_m=1e9), T0)
    assert err.value.field == "max_alt_amsl_m" and "20000" in err.value.reason


def test_codec_modules_split_by_responsibility_and_re_exported() -> None:
    import adapters.mqtt.codec as codec
    from adapters.mqtt import encode, topics, wire

    for module in (codec, encode, topics, wire):
        assert module.__file__ is not None
        assert len(Path(module.__file__).read_text().splitlines()) < 800
    assert codec.Topics is topics.Topics and codec.encode_alert is encode.encode_alert
    assert codec.MqttMessageError is wire.MqttMessageError
    assert set(codec.__all__) <= set(dir(codec))


def test_nesting_is_bounded_like_every_other_input() -> None:
    deep = '{"a": ' + "[" * 100 + "]" * 100 + "}"
    with pytest.raises(MqttMessageError, match="nested deeper than 64 levels"):
        decode(T, T.answers("alice"), deep, 0.0)
    deeper = "[" * 100_000 + "]" * 100_000
    with pytest.raises(MqttMessageError, match="nested deeper than 64 levels"):
        decode(T, T.answers("alice"), deeper, 0.0)


def test_a_sysid_conflict_is_published_as_a_valid_alert() -> None:
    from adapters.mqtt.encode import encode_alert
    from gcs_utm.model import Threat

    claim = Threat(
        id=ThreatId("sysid_conflict-1"),
        kind=ThreatKind.SYSID_CONFLICT,
        uas_ids=(OperationId("op"),),
        detected_at_s=T0,
        message="sysid 1 claimed by another sender",
    )
    obj = json.loads(encode_alert(claim))
    validate("alert", obj)
    assert obj["kind"] == "SYSID_CONFLICT" and obj["operation_ids"] == ["op"]


def test_operator_command_decodes_with_the_topic_s_operator_and_refuses_the_rest() -> None:
    from adapters.mqtt.codec import OperatorCommandRequest, encode_command_status

    good = {"schema_version": 1, "type": "operator_command", "uas": "UAS1", "command": "rtl"}
    msg = decode(T, T.commands("alice"), json.dumps({**good, "id": "c1"}), 5.0)
    assert msg == OperatorCommandRequest(
        uas="UAS1", command="rtl", request_id="c1", operator="alice", t_s=5.0
    )
    for field, obj in {
        "command": {**good, "id": "c1", "command": "loop"},
        "id": good,  # an id is needed to acknowledge it
        "operator": {**good, "id": "c1", "operator": "bob"},  # the topic says who
    }.items():
        with pytest.raises(MqttMessageError) as err:
            decode(T, T.commands("alice"), json.dumps(obj), 0.0)
        assert field in str(err.value) or "additional" in str(err.value), err.value
    status = json.loads(
        encode_command_status(
            request_id="c1",
            uas="UAS1",
            command="rtl",
            t_s=1.0,
            outcome="refused",
            reason="sysid 1 is disarmed",
            mode="",
        )
    )
    validate("command_status", status)
