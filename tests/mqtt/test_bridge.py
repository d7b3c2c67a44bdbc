"""The bridge against a real mosquitto with passwords and the per-operator ACL."""

from __future__ import annotations

import asyncio
import json
from dataclasses import replace
from typing import Any

import pytest
from mqtt_helpers import T0, Broker, FakeUsm, peer

from adapters.mqtt.bridge import MqttBridge
from adapters.mqtt.codec import Topics
from gcs_utm.clock import ManualClock
from gcs_utm.messages import PilotDecision
from gcs_utm.model import (
    Alternative,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
    LatLon,
    Maneuver,
    MeasurementSource,
    OperationId,
    Position,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
    Track,
    TrackId,
    Waypoint4D,
)

pytestmark = [pytest.mark.mqtt, pytest.mark.network]

T = Topics("gcs_utm")
OP = OperationId("op-alice-1")


def _plan(version: int = 1, t0: float = T0) -> FlightPlan:
    return FlightPlan(
        operation_id=OP,
        version=version,
        waypoints=(
            Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0, t_s=t0),
            Waypoint4D(lat_deg=40.001, lon_deg=-3.0, alt_amsl_m=710.0, t_s=t0 + 20.0),
        ),
    )


def _rec(version: int = 1, deadline: float = T0 + 60.0) -> Recommendation:
    alt = Alternative(
        operation_id=OP, maneuver=Maneuver.GO_UP, plan=_plan(version + 1), cost=0.2, risk=0.1
    )
    other = Alternative(operation_id=OP, maneuver=Maneuver.HOLD, plan=None, cost=0.5, risk=0.05)
    return Recommendation(
        id=RecommendationId("rec-1"),
        version=version,
        threat_id=ThreatId("thr-1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=T0,
        deadline_t_s=deadline,
        selected=alt,
        alternatives=(alt, other),
    )


def _answer(version: int, decision: str = "accept", rec_id: str = "rec-1") -> dict[str, Any]:
    return {
        "schema_version": 1,
        "type": "pilot_answer",
        "recommendation_id": rec_id,
        "version": version,
        "decision": decision,
        "t_s": T0 + 1.0,
    }


def _fence(gid: str = "gf-1") -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=1000.0,
        center=LatLon(lat_deg=40.0, lon_deg=-3.0),
        radius_m=300.0,
        kind=GeofenceKind.DYNAMIC,
        reason="wildfire",
    )


async def test_inbound_round_trip_of_every_message_type(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    async with (
        MqttBridge(broker.config(), clock, usm) as bridge,
        peer(broker, "alice", (T.status("alice"), T.errors_for("alice"))) as alice,
        peer(broker, "authority") as authority,
        peer(broker, "adsb") as adsb,
    ):
        await bridge.wait_connected(5.0)
        await alice.send(
            T.state("alice"),
            {
                "schema_version": 1,
                "type": "rpa_state",
                "operation_id": OP,
                "icao24": "34A1B2",
                "t_s": T0,
                "lat_deg": 40.0,
                "lon_deg": -3.0,
                "alt_amsl_m": 712.5,
                "covariance_h_m2": 4.0,
                "gnss": {"jamming": True, "hpl_m": 40.0, "hal_m": 25.0},
            },
        )
        await adsb.send(
            T.adsb,
            {
                "schema_version": 1,
                "type": "adsb",
                "icao24": "4ca1fe",
                "callsign": "IBE123 ",
                "t_s": T0,
                "lat_deg": 40.1,
                "lon_deg": -3.1,
                "alt_amsl_m": 1500.0,
                "heading_deg": 90.0,
                "ground_speed_mps": 100.0,
            },
        )
        await alice.send(
            T.flight_plans("alice"),
            {
                "schema_version": 1,
                "type": "flight_plan",
                "operation_id": OP,
                "t_s": T0,
                "waypoints": [
                    {"lat_deg": 40.0, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0},
                    {"lat_deg": 40.01, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0 + 100},
                ],
                "cruise_speed_mps": 12.0,
            },
        )
        await alice.send(
            T.flight_status("alice"),
            {
                "schema_version": 1,
                "type": "flight_status",
                "operation_id": OP,
                "status": "start",
                "t_s": T0,
            },
        )
        await authority.send(
            T.airspace_alerts,
            {
                "schema_version": 1,
                "type": "airspace_alert",
                "alert_id": "fire-7",
                "category": "wildfire",
                "t_s": T0,
                "geometry": {
                    "shape": "polygon",
                    "vertices": [
                        {"lat_deg": 40.0, "lon_deg": -3.0},
                        {"lat_deg": 40.01, "lon_deg": -3.0},
                        {"lat_deg": 40.01, "lon_deg": -2.99},
                    ],
                },
                "min_alt_amsl_m": 0.0,
                "max_alt_amsl_m": 3000.0,
                "end_t_s": T0 + 3600,
            },
        )
        usm.book.register(_rec(), "alice")
        await alice.send(T.answers("alice"), _answer(1))
        await usm.wait_for(
            lambda: (
                len(usm.measurements) == 2
                and len(usm.hazards) == 3
                and usm.plans
                and usm.statuses
                and usm.answers
            )
        )
        tel = next(m for m in usm.measurements if m.source is MeasurementSource.MQTT)
        assert tel.operation_id == OP and tel.icao24 == "34a1b2" and tel.alt_amsl_m == 712.5
        assert tel.eph_m == pytest.approx(2.0) and tel.link == "mqtt:alice"
        ads = next(m for m in usm.measurements if m.source is MeasurementSource.ADSB)
        assert ads.icao24 == "4ca1fe" and ads.callsign == "IBE123"
        assert ads.vel_ned_mps == pytest.approx((0.0, 100.0, 0.0), abs=1e-9)
        kinds = sorted(h.kind.value for h in usm.hazards)
        assert kinds == ["ALERT_WARNING", "GNSS_DEGRADATION", "JAMMING_ATTACK"]
        fire = next(h for h in usm.hazards if h.kind is ThreatKind.ALERT_WARNING)
        assert fire.area is not None and len(fire.area.vertices) == 3
        assert fire.area.end_t_s == T0 + 3600 and fire.area.max_alt_amsl_m == 3000.0
        assert usm.plans[0].operator == "alice" and len(usm.plans[0].plan.waypoints) == 2
        assert usm.plans[0].to_operation().cruise_speed_mps == 12.0
        assert usm.statuses[0].status.value == "start"
        assert usm.answers[0].operator == "alice"
        _, status, _ = await alice.next(T.status("alice"))
        assert status["answer"] == {"outcome": "accepted", "decision": "accept", "version": 1}
        assert status["state"] == "accepted"
        assert alice.empty_for() == []  # no error was reported for any of these
        assert bridge.stats.rejected == 0


async def test_outbound_round_trip_and_retained_geofences(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    subs = (
        T.alerts_for("alice"),
        T.recommendations("alice"),
        T.status("alice"),
        T.alerts,
        T.traffic,
        T.geofence_events,
    )
    async with (
        MqttBridge(broker.config(), clock, usm) as bridge,
        peer(broker, "alice", subs) as alice,
    ):
        await bridge.wait_connected(5.0)
        threat = Threat(
            id=ThreatId("thr-1"),
            kind=ThreatKind.GEOFENCE_CONFLICT,
            uas_ids=(OP,),
            detected_at_s=T0,
            predicted_event_at_s=T0 + 30.0,
            position=Position(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0),
            message="conflict with wildfire area",
        )
        bridge.publish_alert(threat, ["alice"])
        bridge.publish_alert(threat)
        rec = _rec()
        bridge.publish_recommendation(rec, "alice")
        bridge.publish_recommendation_status(rec.transition(RecommendationState.EXPIRED, T0 + 61))
        track = Track(
            id=TrackId("op-alice-1"),
            t_s=T0,
            lat_deg=40.0,
            lon_deg=-3.0,
            alt_amsl_m=700.0,
            east_m=0.0,
            north_m=0.0,
            vel_enu_mps=(3.0, 4.0, 0.0),
            position_sigma_m=1.5,
            cooperative=True,
            operation_id=OP,
        )
        assert bridge.publish_traffic([track])
        assert not bridge.publish_traffic([track])  # rate limit on the injected clock
        bridge.publish_geofences([_fence("gf-1"), _fence("gf-2")])
        bridge.publish_geofences([_fence("gf-2")])

        _, a1, _ = await alice.next(T.alerts_for("alice"))
        assert a1["alert_id"] == "thr-1" and a1["kind"] == "GEOFENCE_CONFLICT"
        assert a1["position"]["alt_amsl_m"] == 700.0
        _, a2, _ = await alice.next(T.alerts)
        assert a2 == a1
        _, r, _ = await alice.next(T.recommendations("alice"))
        assert (r["recommendation_id"], r["version"], r["deadline_t_s"]) == ("rec-1", 1, T0 + 60)
        assert r["selected"]["maneuver"] == "go_up" and len(r["selected"]["waypoints"]) == 2
        assert [a["cost"] for a in r["alternatives"]] == [0.2, 0.5]
        _, st, _ = await alice.next(T.status("alice"))
        assert st["state"] == "expired" and st["answer"] is None
        _, tr, _ = await alice.next(T.traffic)
        assert tr["tracks"][0]["ground_speed_mps"] == pytest.approx(5.0)
        events = [(await alice.next(T.geofence_events))[1] for _ in range(3)]
        assert [(e["action"], e["geofence"]["id"]) for e in events] == [
            ("created", "gf-1"),
            ("created", "gf-2"),
            ("removed", "gf-1"),
        ]
        await bridge.flush()

        # a late subscriber gets the current active set at once (retained)
        async with peer(broker, "bob", (T.geofences, T.bridge)) as late:
            got = {}
            for _ in range(2):
                topic, obj, retained = await late.next()
                assert retained
                got[topic] = obj
            assert [g["id"] for g in got[T.geofences]["geofences"]] == ["gf-2"]
            assert got[T.bridge]["online"] is True


async def test_pilot_answer_semantics_over_mqtt(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    async with (
        MqttBridge(broker.config(), clock, usm) as bridge,
        peer(broker, "alice", (T.recommendations("alice"), T.status("alice"))) as alice,
    ):
        await bridge.wait_connected(5.0)
        v1 = _rec(1)
        usm.book.register(v1, "alice")
        bridge.publish_recommendation(v1, "alice")
        _, shown, _ = await alice.next(T.recommendations("alice"))
        # EM re-plans before the pilot answers: version 2 supersedes version 1
        v2 = replace(v1, version=2)
        usm.book.register(v2, "alice")
        bridge.publish_recommendation(v2, "alice")

        async def answer(obj: dict[str, Any]) -> dict[str, Any]:
            await alice.send(T.answers("alice"), obj)
            return (await alice.next(T.status("alice")))[1]

        late = await answer(_answer(shown["version"], "reject"))
        assert late["answer"]["outcome"] == "refused" and "superseded" in late["reason"]
        ok = await answer({**_answer(2), "alternative_index": 0})
        assert ok["answer"]["outcome"] == "accepted" and ok["state"] == "accepted"
        dup = await answer({**_answer(2), "alternative_index": 0})
        assert dup["answer"]["outcome"] == "duplicate" and dup["state"] == "accepted"
        flip = await answer(_answer(2, "reject"))
        assert flip["answer"]["outcome"] == "refused" and "already answered" in flip["reason"]
        assert [o.status.value for o in usm.outcomes] == [
            "refused",
            "accepted",
            "duplicate",
            "refused",
        ]
        assert usm.book.get(RecommendationId("rec-1")).state is RecommendationState.ACCEPTED  # type: ignore[union-attr]

        # an answer after the deadline is refused with a reason
        usm.book.register(replace(_rec(1), id=RecommendationId("rec-2")), "alice")
        clock.set(T0 + 61.0)
        expired = await answer(_answer(1, rec_id="rec-2"))
        assert expired["answer"]["outcome"] == "refused" and expired["state"] == "expired"
        assert "expired" in expired["reason"]


async def test_acl_one_operator_cannot_answer_or_read_for_another(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    async with (
        MqttBridge(broker.config(), clock, usm) as bridge,
        peer(broker, "alice", (T.recommendations("alice"), T.status("alice"))) as alice,
        peer(
            broker,
            "bob",
            (T.recommendations("alice"), T.status("bob"), T.status("alice"), T.answers("alice")),
        ) as bob,
    ):
        await bridge.wait_connected(5.0)
        rec = _rec(1)
        usm.book.register(rec, "alice")
        bridge.publish_recommendation(rec, "alice")
        await alice.next(T.recommendations("alice"))
        # bob publishes on alice's answer topic: the broker drops it (ACL write denied)
        await bob.send(T.answers("alice"), _answer(1, "reject"))
        # bob answers alice's recommendation on his own topic: the USM refuses it
        await bob.send(T.answers("bob"), _answer(1, "reject"))
        _, refused, _ = await bob.next(T.status("bob"))
        assert refused["answer"]["outcome"] == "refused" and "bob" in refused["reason"]
        # alice's own answer is the one that counts
        await alice.send(T.answers("alice"), _answer(1, "accept"))
        _, ok, _ = await alice.next(T.status("alice"))
        assert ok["answer"]["outcome"] == "accepted"
        assert [(a.operator, a.decision) for a in usm.answers] == [
            ("bob", PilotDecision.REJECT),
            ("alice", PilotDecision.ACCEPT),
        ]
        await asyncio.sleep(0.2)
        # bob never saw alice's recommendation, status, nor her answer topic
        assert bob.empty_for() == []


async def test_broker_restart_mid_session_loses_no_answer(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    rps = {"client_id": "rps-alice", "clean": False}  # the station's persistent session
    subs = (T.recommendations("alice"), T.status("alice"))
    async with MqttBridge(broker.config(), clock, usm) as bridge:
        await bridge.wait_connected(5.0)
        async with peer(broker, "alice", subs, **rps):  # type: ignore[arg-type]
            pass  # the session (subscriptions) exists; the station goes away
        rec = _rec(1)
        usm.book.register(rec, "alice")
        broker.stop()
        await asyncio.sleep(0.2)
        assert not bridge.connected
        # produced while the broker is down: queued in the bridge, sent after reconnect
        bridge.publish_recommendation(rec, "alice")
        assert bridge.pending >= 1
        broker.start()
        await bridge.wait_connected(10.0)
        await bridge.flush()
        async with peer(broker, "alice", subs, **rps) as alice:  # type: ignore[arg-type]
            # kept for the station's session by the restarted broker (QoS 1, persistence)
            _, shown, _ = await alice.next(T.recommendations("alice"), timeout_s=10.0)
            assert (shown["recommendation_id"], shown["version"]) == ("rec-1", 1)
            # the station answers (QoS 1: the broker has it) and the broker dies at once,
            # whether or not the bridge had handled it yet
            await alice.send(T.answers("alice"), _answer(1))
            broker.stop()
        broker.start()
        async with peer(broker, "alice", subs, **rps) as alice:  # type: ignore[arg-type]
            _, status, _ = await alice.next(T.status("alice"), timeout_s=10.0)
            assert status["answer"]["outcome"] in {"accepted", "duplicate"}
            assert status["state"] == "accepted"
        assert len(usm.answers) >= 1
        assert usm.outcomes[0].status.value == "accepted"
        assert usm.book.get(rec.id).state is RecommendationState.ACCEPTED  # type: ignore[union-attr]
        assert bridge.stats.connection_losses >= 1 and bridge.stats.connects >= 2


async def test_thousand_malformed_messages_never_crash(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    bad: list[bytes] = []
    for i in range(1000):
        k = i % 8
        if k == 0:
            bad.append(b"{not json" + str(i).encode())
        elif k == 1:
            bad.append(b"\xff\xfe" + bytes([i % 256]))
        elif k == 2:
            bad.append(json.dumps(_answer(-i)).encode())  # negative version
        elif k == 3:
            bad.append(json.dumps({**_answer(1), "decision": "maybe"}).encode())
        elif k == 4:
            bad.append(b'{"schema_version":1,"type":"pilot_answer","t_s":NaN}')
        elif k == 5:
            bad.append(json.dumps([1, 2, i]).encode())
        elif k == 6:
            bad.append(b"[" * 5000)
        else:
            bad.append(json.dumps({**_answer(1), "schema_version": 99}).encode())
    async with (
        MqttBridge(broker.config(queue_max=5000), clock, usm) as bridge,
        peer(broker, "alice", (T.errors_for("alice"), T.status("alice"))) as alice,
    ):
        await bridge.wait_connected(5.0)
        for payload in bad:
            await alice.send(T.answers("alice"), payload, qos=0)
        # unknown operation on an operator topic (the ACL stops operators from writing
        # there; a client with broad rights, like a mis-configured tool, can)
        async with peer(broker, "gcs_utm") as tool:
            await tool.send(T.operator("alice", "launch_missiles"), {"x": 1})
        errors = [(await alice.next(T.errors_for("alice"), timeout_s=20.0))[1] for _ in range(1001)]
        assert all(e["reason"] for e in errors)
        # from another client, so not necessarily last (no order across publishers)
        assert sum("unknown operation" in e["reason"] for e in errors) == 1
        assert {e["field"] for e in errors} >= {"", "version", "decision", "schema_version"}
        assert bridge.stats.rejected == 1001 and usm.answers == []
        # still alive and serving
        usm.book.register(_rec(1), "alice")
        await alice.send(T.answers("alice"), _answer(1))
        _, ok, _ = await alice.next(T.status("alice"))
        assert ok["answer"]["outcome"] == "accepted"
