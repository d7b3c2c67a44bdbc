"""Pilot answers survive the UTM's absence and a broker restart with mosquitto's default
settings (no persistence): MQTT 5 session with an expiry interval, QoS 1 answers, and the
recommendations still waiting for an answer re-published on every reconnect."""

from __future__ import annotations

import asyncio
import random
from pathlib import Path

import pytest
from mqtt_helpers import Broker, FakeUsm, make_broker, peer
from test_bridge import T, _answer, _rec

from adapters.mqtt.bridge import MqttBridge
from adapters.mqtt.station import PilotStation
from gcs_utm.clock import ManualClock
from gcs_utm.messages import PilotDecision
from gcs_utm.model import RecommendationState

pytestmark = [pytest.mark.mqtt, pytest.mark.network]

T0 = 1_700_000_000.0


@pytest.fixture
def plain_broker(tmp_path: Path) -> Broker:
    b = make_broker(tmp_path, persistence=False)
    try:
        yield b  # type: ignore[misc]
    finally:
        b.stop()


async def test_answer_sent_while_the_utm_is_away_is_delivered(plain_broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    usm.book.register(_rec(1), "alice")
    async with MqttBridge(plain_broker.config(), clock, usm) as bridge:
        await bridge.wait_connected(5.0)  # the session and its subscriptions exist
    async with peer(plain_broker, "alice") as alice:
        await alice.send(T.answers("alice"), _answer(1))  # QoS 1, the UTM is away
    async with MqttBridge(plain_broker.config(), clock, usm) as bridge:
        await bridge.wait_connected(5.0)
        # kept in the broker's memory for the UTM's session (expiry interval > 0)
        await usm.wait_for(lambda: bool(usm.answers), timeout_s=5.0)
    assert usm.outcomes[0].status.value == "accepted"


async def test_broker_restart_without_persistence_re_requests_pending_answers(
    plain_broker: Broker,
) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    rec = _rec(1)
    usm.book.register(rec, "alice")
    cfg = plain_broker.config(backoff_initial_s=1.0, backoff_max_s=1.0)
    subs = (T.recommendations("alice"), T.status("alice"))
    async with MqttBridge(cfg, clock, usm) as bridge:
        await bridge.wait_connected(5.0)
        async with peer(plain_broker, "alice", subs) as alice:
            bridge.publish_recommendation(rec, "alice")
            await alice.next(T.recommendations("alice"))
        assert bridge.outstanding == [rec.id]
        plain_broker.stop()  # forgets every session: the UTM's subscriptions too
        async with asyncio.timeout(5.0):
            while bridge.connected:
                await asyncio.sleep(0.02)
        plain_broker.start()
        # the station is back first; it answers what it is asked (again)
        async with peer(plain_broker, "alice", subs) as alice:
            _, shown, _ = await alice.next(T.recommendations("alice"), timeout_s=10.0)
            assert (shown["recommendation_id"], shown["version"]) == ("rec-1", 1)
            await alice.send(T.answers("alice"), _answer(1))
            _, status, _ = await alice.next(T.status("alice"), timeout_s=10.0)
        assert status["answer"]["outcome"] == "accepted"
        assert bridge.outstanding == []  # answered: not asked again
    assert usm.book.get(rec.id).state is RecommendationState.ACCEPTED  # type: ignore[union-attr]


async def test_an_answer_sent_during_a_broker_restart_is_resent_until_acknowledged(
    plain_broker: Broker,
) -> None:
    """The station is back before gcs-utm after a broker restart without persistence: its
    first send reaches nobody (no session, no subscription for gcs-utm yet). The project's
    station keeps the answer until gcs-utm acknowledges it on the status topic, and re-sends
    it when gcs-utm announces it is online again: it is taken exactly once."""
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    rec = _rec(1)
    usm.book.register(rec, "alice")
    # gcs-utm's first reconnect waits 1.5-3 s; the station's 0.025-0.1 s
    utm = plain_broker.config(backoff_initial_s=3.0, backoff_max_s=3.0)
    alice = plain_broker.config("alice", backoff_initial_s=0.05, backoff_max_s=0.1)
    async with (
        MqttBridge(utm, clock, usm, rng=random.Random(1)) as bridge,
        PilotStation(alice, "alice", clock, resend_s=60.0) as station,
    ):
        await bridge.wait_connected(5.0)
        # a recommendation is not retained: one published before the station subscribed
        # reaches nobody (on a loaded machine the station can be the later one)
        async with asyncio.timeout(10.0):
            while not station.connected:
                await asyncio.sleep(0.02)
        bridge.publish_recommendation(rec, "alice")
        shown = await asyncio.wait_for(station.recommendations.get(), 5.0)
        connects = station.connects
        plain_broker.stop()  # forgets every session and subscription
        async with asyncio.timeout(5.0):
            while bridge.connected or station.connects == connects:
                await asyncio.sleep(0.02)
                if not bridge.connected and plain_broker.proc is None:
                    plain_broker.start()
        assert not bridge.connected  # nobody receives the answer now
        ack = await station.answer(
            shown["recommendation_id"], shown["version"], PilotDecision.ACCEPT, timeout_s=15.0
        )
        assert station.unacknowledged == []
    assert (ack.outcome, ack.state) == ("accepted", "accepted")
    assert station.sent[("rec-1", 1)] >= 2  # the first send was lost
    assert [o.status.value for o in usm.outcomes].count("accepted") == 1
    assert usm.book.get(rec.id).state is RecommendationState.ACCEPTED  # type: ignore[union-attr]
