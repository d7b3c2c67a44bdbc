"""The ownership rule (who decides a threat) and the region traffic codec, without a broker."""

from __future__ import annotations

from dataclasses import replace

import pytest

from adapters.mqtt.encode import encode_traffic
from adapters.mqtt.wire import MqttMessageError
from gcs_utm.cluster.exchange import decode_traffic, region_topic
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.model import OperationId, Threat, ThreatId, ThreatKind
from gcs_utm.scenario import load_scenario
from tests.store.test_store import UC1, _track


def _policy(foreign: set[str], priorities: dict[str, int]) -> OwnershipPolicy:
    base = load_scenario(UC1).operations[0]
    ops = {
        OperationId(i): replace(
            base,
            id=OperationId(i),
            priority=p,
            plan=replace(base.plan, operation_id=OperationId(i)),
        )
        for i, p in priorities.items()
    }
    policy = OwnershipPolicy()
    policy.operations_of = lambda: ops
    policy.foreign = {OperationId(f) for f in foreign}
    return policy


def _threat(*uas: str) -> Threat:
    return Threat(
        id=ThreatId("T1"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=tuple(OperationId(u) for u in uas),
        detected_at_s=0.0,
    )


def test_the_owner_of_the_higher_priority_uas_decides_and_ties_go_to_the_smaller_id() -> None:
    # instance A owns UAS1 (priority 1) and watches UAS2 (priority 10) of instance B
    a = _policy({"UAS2"}, {"UAS1": 1, "UAS2": 10})
    b = _policy({"UAS1"}, {"UAS1": 1, "UAS2": 10})
    pair = [_threat("UAS1", "UAS2")]
    assert a.filter_threats(pair) == [] and b.filter_threats(pair) == pair
    # equal priorities: the smaller operation id's owner, on both sides alike
    a = _policy({"UAS2"}, {"UAS1": 5, "UAS2": 5})
    b = _policy({"UAS1"}, {"UAS1": 5, "UAS2": 5})
    assert a.filter_threats(pair) == pair and b.filter_threats(pair) == []
    # a foreign UAS's own threats (conformance, geofence) are its owner's
    assert a.filter_threats([_threat("UAS2")]) == []
    mine = [_threat("UAS1")]
    assert a.filter_threats(mine) == mine
    assert a.owns(OperationId("UAS1")) and not a.owns(OperationId("UAS2"))
    assert not a.owns(OperationId("UAS9"))  # not in the airspace at all


def test_traffic_round_trip_skips_intruders_and_refuses_bad_payloads() -> None:
    topic = region_topic("gcs_utm", "c1r0")
    assert topic == "gcs_utm/cluster/regions/c1r0/traffic"
    own = _track(3, 12.5, "sys1")
    intruder = replace(_track(4, 12.5, "icao:3c6444"), operation_id=None, cooperative=False)
    (got,) = decode_traffic(topic, encode_traffic([own, intruder], 13.0), "c1r0")
    assert got.operation_id == "sys1" and got.region_id == "c1r0"
    assert (got.t_s, got.lat_deg, got.lon_deg, got.alt_amsl_m) == (
        own.t_s,
        own.lat_deg,
        own.lon_deg,
        own.alt_amsl_m,
    )
    assert got.vel_enu_mps == own.vel_enu_mps
    with pytest.raises(MqttMessageError, match="malformed JSON"):
        decode_traffic(topic, b"{not json", "c1r0")
    with pytest.raises(MqttMessageError):
        decode_traffic(topic, b'{"type": "traffic"}', "c1r0")
