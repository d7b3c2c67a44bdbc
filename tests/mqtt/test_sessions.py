"""Pilot answers survive the UTM's absence and a broker restart with mosquitto's default
settings (no persistence): MQTT 5 session with an expiry interval, QoS 1 answers, and the
recommendations still waiting for an answer re-published on every reconnect."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from mqtt_helpers import Broker, FakeUsm, make_broker, peer
from test_bridge import T, _answer, _rec

from adapters.mqtt.bridge import MqttBridge
from gcs_utm.clock import ManualClock
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
