"""``gcs-utm pilot``'s station loop in process (gcs_utm/cli/pilot.py ``run_pilot``, stdin
as a queue of lines) against a real mosquitto and the MQTT bridge with a fake USM: a broker
it cannot reach is one line and it keeps retrying; a superseded and an expired
recommendation are said so; an answer sent while gcs-utm is away is re-sent until gcs-utm
acknowledges it."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
from collections.abc import AsyncIterator

import pytest
from mqtt_helpers import Broker, FakeUsm
from test_bridge import _rec

from adapters.mqtt.bridge import MqttBridge
from adapters.mqtt.config import MqttConfig
from gcs_utm.cli.pilot import run_pilot
from gcs_utm.clock import ManualClock
from gcs_utm.model import RecommendationState

pytestmark = [pytest.mark.mqtt, pytest.mark.network]

T0 = 1_700_000_000.0


class _Console:
    """The pilot's terminal: lines typed in, lines printed out."""

    def __init__(self) -> None:
        self.lines: asyncio.Queue[str | None] = asyncio.Queue()
        self.out: list[str] = []
        self._seen = 0
        self._event = asyncio.Event()

    def write(self, text: str) -> None:
        self.out.extend(text.splitlines())
        self._event.set()

    async def until(self, text: str, timeout_s: float = 5.0) -> str:
        """The next printed line (after the last one matched) that contains ``text``."""
        async with asyncio.timeout(timeout_s):
            while True:
                for k in range(self._seen, len(self.out)):
                    if text in self.out[k]:
                        self._seen = k + 1
                        return self.out[k]
                self._event.clear()
                await self._event.wait()


@contextlib.asynccontextmanager
async def _pilot(config: MqttConfig, resend_s: float = 5.0) -> AsyncIterator[_Console]:
    console = _Console()
    task = asyncio.create_task(
        run_pilot(
            config, "alice", console.lines, console.write, resend_s=resend_s, clock=ManualClock(T0)
        )
    )
    try:
        yield console
        console.lines.put_nowait(None)  # Ctrl-D
        assert await asyncio.wait_for(task, 5.0) == 0
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    assert not [line for line in console.out if "Traceback" in line]


async def test_unreachable_broker_is_one_line_and_retried_until_it_is_up(
    broker: Broker,
) -> None:
    broker.stop()
    cfg = broker.config("alice", backoff_initial_s=0.05, backoff_max_s=0.2)
    async with _pilot(cfg) as pilot:
        line = await pilot.until("cannot connect to the MQTT broker")
        assert line.endswith("retrying (Ctrl-D or Ctrl-C to quit)")
        await asyncio.sleep(0.5)  # several failed attempts: still one line
        assert sum("cannot connect" in o for o in pilot.out) == 1
        broker.start()
        await pilot.until("connected to", timeout_s=5.0)


async def test_superseded_and_expired_recommendations_are_said_so(broker: Broker) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    async with MqttBridge(broker.config(), clock, usm) as bridge:
        await bridge.wait_connected(5.0)
        async with _pilot(broker.config("alice")) as pilot:
            await pilot.until("connected to")
            bridge.publish_recommendation(_rec(1), "alice")
            await pilot.until("recommendation rec-1 v1 for UAS op-alice-1")
            v2 = _rec(2)
            bridge.publish_recommendation(v2, "alice")
            assert await pilot.until("superseded") == "recommendation rec-1 v1 superseded by v2"
            await pilot.until("recommendation rec-1 v2 for UAS op-alice-1")
            bridge.publish_recommendation(v2, "alice")  # as after a reconnect: not shown again
            expired = dataclasses.replace(v2, state=RecommendationState.EXPIRED)
            bridge.publish_recommendation_status(expired, "alice")
            assert await pilot.until("EXPIRED") == (
                "!!! EXPIRED recommendation rec-1 v2: nobody answered in time - no longer "
                "answerable"
            )
            pilot.lines.put_nowait("a\n")
            await pilot.until("no recommendation to answer now")
    assert sum("rec-1 v2 for UAS" in line for line in pilot.out) == 1
    assert usm.answers == []


async def test_answer_while_gcs_utm_is_away_is_resent_until_acknowledged(
    broker: Broker,
) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    rec = _rec(1)
    usm.book.register(rec, "alice")
    async with _pilot(broker.config("alice"), resend_s=0.2) as pilot:
        async with MqttBridge(broker.config(), clock, usm) as bridge:
            await bridge.wait_connected(5.0)
            await pilot.until("connected to")
            bridge.publish_recommendation(rec, "alice")
            await pilot.until("recommendation rec-1 v1")
            await bridge.flush(5.0)
        pilot.lines.put_nowait("a 2\n")  # row 2: alternative_index 1 (hold)
        await pilot.until("sending accept (alternative_index 1) for recommendation rec-1 v1")
        await pilot.until("no acknowledgement from gcs-utm yet; re-sending every 0.2 s")
        async with MqttBridge(broker.config(), clock, usm) as bridge:
            line = await pilot.until("gcs-utm accepted the answer")
        assert line == "gcs-utm accepted the answer to recommendation rec-1 v1 (state accepted)"
    assert [a.alternative_index for a in usm.answers][:1] == [1]
    assert [o.status.value for o in usm.outcomes].count("accepted") == 1


async def test_refused_credentials_are_one_line_not_a_traceback(broker: Broker) -> None:
    cfg = broker.config("alice", password="wrong", backoff_initial_s=0.05, backoff_max_s=0.2)
    async with _pilot(cfg) as pilot:
        line = await pilot.until("cannot connect to the MQTT broker")
        assert "authori" in line.lower()  # mosquitto: "Not authorized"


async def test_typed_operator_commands_ask_first_then_print_gcs_utm_s_outcome(
    broker: Broker,
) -> None:
    clock = ManualClock(T0)
    usm = FakeUsm(clock)
    async with MqttBridge(broker.config(), clock, usm) as bridge:
        await bridge.wait_connected(5.0)
        async with _pilot(broker.config("alice")) as pilot:
            await pilot.until("connected to")
            pilot.lines.put_nowait("rtl UAS1\n")
            await pilot.until("rtl UAS1? type y + Enter to send it, anything else cancels")
            pilot.lines.put_nowait("no\n")
            await pilot.until("rtl UAS1 cancelled")
            pilot.lines.put_nowait("hold UAS1\n")
            await pilot.until("hold UAS1?")
            pilot.lines.put_nowait("y\n")
            line = await pilot.until("gcs-utm: hold")
            assert line == "gcs-utm: hold UAS1 confirmed (vehicle reports hold)"
            pilot.lines.put_nowait("land nope\n")
            pilot.lines.put_nowait("y\n")
            line = await pilot.until("gcs-utm: land")
            assert line == "gcs-utm: land nope refused (unknown UAS 'nope')"
    assert [(c.operator, c.uas, c.command) for c in usm.commands] == [
        ("alice", "UAS1", "hold"),
        ("alice", "nope", "land"),
    ]
