"""MQTT gateway end to end: a real mosquitto (tests/mqtt/mqtt_helpers: password file + the
gcs-utm ACL), the real USM with a fake vehicle port, a remote pilot station as an MQTT peer.

recommendation -> alice's recommendations topic (schema-valid) -> accept with id + version on
alice's answers topic -> upload to the vehicle -> "applied" on alice's status topic; a wrong
version is refused with its reason and uploads nothing; plans filed over MQTT become
operations, duplicates are refused on the errors topic; new threats become alerts."""

from __future__ import annotations

import asyncio
import contextlib
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "mqtt"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))

from mqtt_helpers import T0, Broker, Peer, make_broker, peer
from usm_fakes import OP, FakeVehicles, make_operation, make_plan

from adapters.mqtt.codec import Topics
from gcs_utm.clock import ManualClock
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    Alternative,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceKind,
    GeofenceShape,
    LatLon,
    Maneuver,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm

T = Topics("gcs_utm")


def _plan(version: int, t0: float = T0) -> FlightPlan:
    return make_plan(version, t0)


def _op() -> Operation:
    return make_operation(T0, operator="alice")


def _rec() -> Recommendation:
    return Recommendation(
        id=RecommendationId("r1"),
        version=1,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=T0,
        deadline_t_s=T0 + 60.0,
        selected=Alternative(
            operation_id=OP, maneuver=Maneuver.GO_DOWN, plan=_plan(1, T0 + 10), cost=1.0, risk=0.1
        ),
    )


@dataclass
class _World:
    usm: Usm
    gateway: MqttGateway
    vehicles: FakeVehicles
    alice: Peer
    broker: Broker
    clock: ManualClock


@contextlib.asynccontextmanager
async def _world(
    tmp_path: Path,
    geofences: tuple[Geofence, ...] = (),
    extra: tuple[str, ...] = (),
    frame: LocalFrame | None = None,
) -> AsyncIterator[_World]:
    broker: Broker = make_broker(tmp_path)
    try:
        clock = ManualClock(T0)
        airspace = Airspace()
        airspace.load([_op()], geofences)
        usm = Usm(airspace, clock)
        vehicles = FakeVehicles()
        usm.attach_vehicles(vehicles)
        gateway = MqttGateway(usm, broker.config(), frame=frame)
        gateway.attach()
        task = asyncio.create_task(gateway.run())
        try:
            async with peer(
                broker,
                "alice",
                (
                    T.recommendations("alice"),
                    T.status("alice"),
                    T.errors_for("alice"),
                    T.alerts_for("alice"),
                    *extra,
                ),
            ) as alice:
                await gateway.bridge.wait_connected(5.0)
                yield _World(usm, gateway, vehicles, alice, broker, clock)
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await usm.drain()
            await usm.close()
    finally:
        broker.stop()


def _answer(version: int, decision: str = "accept") -> dict[str, Any]:
    return {
        "schema_version": 1,
        "type": "pilot_answer",
        "recommendation_id": "r1",
        "version": version,
        "decision": decision,
        "t_s": T0 + 1.0,
    }


async def _status_until(alice: Peer, cond: Any) -> list[dict[str, Any]]:
    seen: list[dict[str, Any]] = []
    while True:
        _, obj, _ = await alice.next(T.status("alice"))
        seen.append(obj)
        if cond(obj):
            return seen


async def test_accept_over_mqtt_uploads_and_reports_applied(tmp_path: Path) -> None:
    async with _world(tmp_path) as w:
        await w.usm.on_recommendation(_rec())
        _, rec, _ = await w.alice.next(T.recommendations("alice"))  # schema-validated by peer
        assert rec["type"] == "recommendation"
        assert (rec["recommendation_id"], rec["version"]) == ("r1", 1)

        await w.alice.send(T.answers("alice"), _answer(rec["version"]))
        seen = await _status_until(w.alice, lambda o: o["state"] == "applied")
        outcomes = [o["answer"] for o in seen if o["answer"] is not None]
        assert outcomes == [{"outcome": "accepted", "decision": "accept", "version": 1}]
        assert [o["state"] for o in seen if o["answer"] is None] == [
            "accepted",
            "uploading",
            "applied",
        ]
        assert len(w.vehicles.uploads) == 1
        record = w.usm.recommendations[RecommendationId("r1")]
        assert record.rec.state is RecommendationState.APPLIED and record.verified
        assert w.usm.airspace.operation(OP).plan.version == 2


async def test_wrong_version_is_refused_with_reason_and_uploads_nothing(tmp_path: Path) -> None:
    async with _world(tmp_path) as w:
        await w.usm.on_recommendation(_rec())
        await w.alice.next(T.recommendations("alice"))
        await w.alice.send(T.answers("alice"), _answer(2))
        _, status, _ = await w.alice.next(T.status("alice"))
        assert status["answer"]["outcome"] == "refused"
        assert "version 2" in status["reason"]
        assert status["state"] == "proposed"
        await w.usm.drain()
        assert w.vehicles.uploads == []
        assert w.usm.recommendations[RecommendationId("r1")].rec.state is (
            RecommendationState.PROPOSED
        )
        assert w.usm.counters["answers_refused"] == 1


async def test_flight_plan_creates_operation_duplicate_refused_and_threat_alerted(
    tmp_path: Path,
) -> None:
    async with _world(tmp_path) as w:
        plan = {
            "schema_version": 1,
            "type": "flight_plan",
            "operation_id": "UAS2",
            "t_s": T0,
            "waypoints": [
                {"lat_deg": 40.0, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0},
                {"lat_deg": 40.01, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0 + 100},
            ],
        }
        await w.alice.send(T.flight_plans("alice"), plan)
        await w.alice.send(T.flight_plans("alice"), plan)
        _, err, _ = await w.alice.next(T.errors_for("alice"))
        assert "already exists" in err["reason"]
        op = w.usm.airspace.operation(OperationId("UAS2"))
        assert op.operator == "alice"
        assert op.priority == w.usm.config.default_priority
        assert op.flight_geometry_m == w.usm.config.default_flight_geometry_m

        threat = Threat(
            id=ThreatId("thr-9"),
            kind=ThreatKind.LOSS_OF_SEPARATION,
            uas_ids=(OP,),
            detected_at_s=T0,
            predicted_event_at_s=T0 + 20.0,
        )
        await w.usm.on_threats([threat])
        await w.usm.on_threats([threat])  # Monitoring repeats a live threat: one alert only
        _, alert, _ = await w.alice.next(T.alerts_for("alice"))
        assert alert["type"] == "alert"
        await w.gateway.bridge.flush(5.0)
        await asyncio.sleep(0.2)
        assert not [m for m in w.alice.empty_for() if m[0] == T.alerts_for("alice")]


async def test_a_flight_plan_into_an_active_geofence_is_refused_with_a_fix(
    tmp_path: Path,
) -> None:
    # A fire fence around (40.0, -3.0): a plan that ends at its centre is refused with one
    # error naming the operation, the fence, the waypoint and a fix; one beside it is filed.
    fence = _fence("fire", None)
    plan = {
        "schema_version": 1,
        "type": "flight_plan",
        "operation_id": "UAS3",
        "t_s": T0,
        "waypoints": [
            {"lat_deg": 40.01, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0},
            {"lat_deg": 40.0, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0 + 100},
        ],
    }
    async with _world(tmp_path, (fence,), frame=LocalFrame(40.0, -3.0, 600.0)) as w:
        await w.alice.send(T.flight_plans("alice"), plan)
        _, err, _ = await w.alice.next(T.errors_for("alice"))
        reason = err["reason"]
        assert "operation UAS3" in reason and "geofence fire" in reason, reason
        assert "waypoint 1 (the destination)" in reason and "fix: move waypoint 1" in reason
        assert OperationId("UAS3") not in w.usm.airspace.operations
        beside = [
            {"lat_deg": 40.01, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0},
            {"lat_deg": 40.02, "lon_deg": -3.0, "alt_amsl_m": 700.0, "t_s": T0 + 100},
        ]
        await w.alice.send(T.flight_plans("alice"), {**plan, "waypoints": beside})
        for _ in range(500):  # filed when the gateway has handled the message
            if OperationId("UAS3") in w.usm.airspace.operations:
                break
            await asyncio.sleep(0.01)
        assert OperationId("UAS3") in w.usm.airspace.operations


def _fence(gid: str, end_t_s: float | None) -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=1000.0,
        center=LatLon(lat_deg=40.0, lon_deg=-3.0),
        radius_m=200.0,
        kind=GeofenceKind.DYNAMIC,
        reason="wildfire",
        end_t_s=end_t_s,
    )


async def _fence_ids(peer_: Peer) -> list[str]:
    _, obj, _ = await peer_.next(T.geofences)
    return sorted(g["id"] for g in obj["geofences"])


async def test_an_expired_geofence_leaves_the_retained_set(tmp_path: Path) -> None:
    """A dynamic geofence that expires is taken out of the retained set (and announced as
    removed) on the clock, without any other change of the set: neither a subscriber nor a
    late one keeps seeing it."""
    permanent = _fence("gf-perm", None)
    async with _world(
        tmp_path, geofences=(permanent,), extra=(T.geofences, T.geofence_events)
    ) as w:
        assert await _fence_ids(w.alice) == ["gf-perm"]  # retained at subscription
        short = _fence("gf-short", T0 + 30.0)
        await w.usm.add_geofences([short])
        assert await _fence_ids(w.alice) == ["gf-perm", "gf-short"]
        _, created, _ = await w.alice.next(T.geofence_events)
        assert (created["action"], created["geofence"]["id"]) == ("created", "gf-short")
        # Nothing else happens: the gateway's own timer (on the injected clock) fires.
        assert await _fence_ids(w.alice) == ["gf-perm"]
        _, removed, _ = await w.alice.next(T.geofence_events)
        assert (removed["action"], removed["geofence"]["id"]) == ("removed", "gf-short")
        assert w.clock.now_s() > T0 + 30.0
        await w.gateway.bridge.flush(5.0)
        async with peer(w.broker, "bob", (T.geofences,)) as late:
            _, obj, retained = await late.next(T.geofences)
            assert retained and [g["id"] for g in obj["geofences"]] == ["gf-perm"]
