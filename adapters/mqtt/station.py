"""The remote pilot station's end of the answer protocol: the project's reference client.

An answer is delivered when gcs-utm says it got it, not when the broker took it: a broker
restarted without persistence (mosquitto's default) forgets gcs-utm's session, and an answer
it receives before gcs-utm has subscribed again reaches nobody. So (docs/mqtt.md, "Answer
delivery"):

- the station keeps each answer until gcs-utm *acknowledges* it: a ``recommendation_status``
  on the operator's ``status`` topic whose ``answer`` names the same recommendation id,
  version and decision (outcome ``accepted``, ``duplicate`` or ``refused`` with its reason);
- until then it re-sends the answer (QoS 1) after each of its own (re)connections, when
  gcs-utm announces it is online (the retained ``bridge_status``, which the bridge publishes
  only once its subscriptions are in place), when gcs-utm re-publishes a recommendation the
  station has answered (gcs-utm re-asks what it has no answer for), and every ``resend_s``;
- gcs-utm takes a repeated answer as a ``duplicate`` and changes nothing, so re-sending
  never changes a decision; it does add an ``answers`` row and an audit entry each time.

Operator commands (hold, land, rtl, resume for one UAS) follow the same rule: each carries an
id, is kept and re-sent until a ``command_status`` naming that id comes back on the ``status``
topic, and gcs-utm carries out an id only once (a repeat gets the first outcome again).

The session is MQTT 5 with a fixed client id, clean start off and the configured session
expiry, subscriptions at QoS 1 (a broker that keeps the session delivers what was published
while the station was away). Reconnects back off like the bridge's (equal jitter).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import random
import uuid
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import aiomqtt

from adapters.mqtt.client import session_client
from adapters.mqtt.config import MqttConfig
from adapters.mqtt.topics import Topics
from gcs_utm.clock import Clock
from gcs_utm.messages import PilotDecision

_log = logging.getLogger(__name__)

_QOS = 1


@dataclass(frozen=True, slots=True)
class AnswerAck:
    """gcs-utm's acknowledgement of one answer: ``outcome`` is ``accepted``, ``duplicate`` or
    ``refused`` (then ``reason`` says why); ``state`` is the recommendation's state after it."""

    recommendation_id: str
    version: int
    decision: str
    outcome: str
    state: str | None
    reason: str


@dataclass(frozen=True, slots=True)
class CommandAck:
    """gcs-utm's outcome of one operator command: ``outcome`` is ``confirmed`` (the vehicle
    reports the mode), ``acknowledged``, ``failed`` or ``refused`` (``reason`` says why)."""

    request_id: str
    uas: str
    command: str
    outcome: str
    reason: str
    mode: str


@dataclass(slots=True)
class _PendingCommand:
    payload: bytes
    acked: asyncio.Future[CommandAck]


@dataclass(slots=True)
class _Pending:
    payload: bytes
    decision: str
    acked: asyncio.Future[AnswerAck]


class PilotStation:
    """``async with PilotStation(config, "alice", clock) as station:`` connects as operator
    ``alice`` (``config.username``/``password`` are its broker credentials; ``client_id``
    names its session, ``station-<operator>`` by default: never the UTM's own) until the
    block exits. :attr:`recommendations` receives each
    ``recommendation`` message (decoded JSON), :attr:`statuses` each state change of a
    recommendation (a ``recommendation_status`` that is not an acknowledgement: expired,
    superseded, applied, ...); :meth:`answer` sends an answer and returns gcs-utm's
    acknowledgement. :attr:`connected` and :attr:`last_error` say how the broker is."""

    def __init__(
        self,
        config: MqttConfig,
        operator: str,
        clock: Clock,
        *,
        resend_s: float = 5.0,
        client_id: str | None = None,
        rng: random.Random | None = None,
    ) -> None:
        if not resend_s > 0.0:
            raise ValueError(f"resend_s: expected a positive number of seconds, got {resend_s}")
        self._config = config
        self.operator = operator
        self._clock = clock
        self.resend_s = resend_s
        self.client_id = client_id or f"station-{operator}"
        self._rng = rng or random.Random()
        self.topics = Topics(config.topic_prefix)
        self.recommendations: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.statuses: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        # why the last connection attempt failed or the connection dropped ("" if none yet)
        self.last_error = ""
        self._pending: dict[tuple[str, int], _Pending] = {}
        self._commands: dict[str, _PendingCommand] = {}  # by request id, until acknowledged
        self._client: aiomqtt.Client | None = None
        self._task: asyncio.Task[None] | None = None
        self.connects = 0
        # how many times each answer was published, by (recommendation id, version)
        self.sent: dict[tuple[str, int], int] = {}

    async def __aenter__(self) -> PilotStation:
        self._task = asyncio.create_task(self._run(), name=f"station-{self.operator}")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                current = asyncio.current_task()
                if current is not None and current.cancelling():
                    raise  # the closer itself is cancelled: not the station's own end
            self._task = None

    @property
    def connected(self) -> bool:
        """Whether the station is connected and subscribed now."""
        return self._client is not None

    @property
    def unacknowledged(self) -> list[tuple[str, int]]:
        """(recommendation id, version) of the answers gcs-utm has not acknowledged yet."""
        return list(self._pending)

    async def answer(
        self,
        recommendation_id: str,
        version: int,
        decision: PilotDecision,
        *,
        alternative_index: int | None = None,
        timeout_s: float | None = None,
    ) -> AnswerAck:
        """Answer one recommendation version and wait for gcs-utm's acknowledgement (raises
        TimeoutError after ``timeout_s``; the answer is still re-sent until acknowledged or
        the station stops)."""
        key = (recommendation_id, version)
        pending = self._pending.get(key)
        if pending is None:
            body: dict[str, Any] = {
                "schema_version": 1,
                "type": "pilot_answer",
                "recommendation_id": recommendation_id,
                "version": version,
                "decision": decision.value,
                "t_s": self._clock.now_s(),
            }
            if alternative_index is not None:
                body["alternative_index"] = alternative_index
            pending = _Pending(
                json.dumps(body).encode(),
                decision.value,
                asyncio.get_running_loop().create_future(),
            )
            self._pending[key] = pending
            await self._send(key)
        return await asyncio.wait_for(asyncio.shield(pending.acked), timeout_s)

    async def command(
        self, uas: str, command: str, *, request_id: str = "", timeout_s: float | None = None
    ) -> CommandAck:
        """Send an operator command (``hold``, ``land``, ``rtl``, ``resume``) for ``uas`` and
        wait for gcs-utm's outcome (raises TimeoutError after ``timeout_s``; the command is
        still re-sent, with the same id, until acknowledged or the station stops)."""
        rid = request_id or uuid.uuid4().hex
        pending = self._commands.get(rid)
        if pending is None:
            body = {
                "schema_version": 1,
                "type": "operator_command",
                "uas": uas,
                "command": command,
                "id": rid,
                "t_s": self._clock.now_s(),
            }
            pending = _PendingCommand(
                json.dumps(body).encode(), asyncio.get_running_loop().create_future()
            )
            self._commands[rid] = pending
            await self._send_command(rid)
        return await asyncio.wait_for(asyncio.shield(pending.acked), timeout_s)

    async def _send_command(self, rid: str) -> None:
        pending = self._commands.get(rid)
        client = self._client
        if pending is None or client is None:
            return
        try:
            await client.publish(self.topics.commands(self.operator), pending.payload, qos=_QOS)
        except aiomqtt.MqttError as exc:  # the connection loop reconnects and re-sends
            _log.info("station %s: command %s not sent: %s", self.operator, rid, exc)

    # ---- the connection ------------------------------------------------------------------
    async def _send(self, key: tuple[str, int]) -> None:
        """Send one unacknowledged answer now if connected (else the next connection will)."""
        pending = self._pending.get(key)
        client = self._client
        if pending is None or client is None:
            return
        self.sent[key] = self.sent.get(key, 0) + 1
        try:
            await client.publish(self.topics.answers(self.operator), pending.payload, qos=_QOS)
        except aiomqtt.MqttError as exc:  # the connection loop reconnects and re-sends
            _log.info("station %s: answer %s v%d not sent: %s", self.operator, *key, exc)

    async def _send_all(self) -> None:
        for key in list(self._pending):
            await self._send(key)
        for rid in list(self._commands):
            await self._send_command(rid)

    def _client_for(self) -> aiomqtt.Client:
        return session_client(self._config, self.client_id)

    async def _run(self) -> None:
        failures = 0
        while True:
            try:
                await self._serve_once()
            except (aiomqtt.MqttError, TimeoutError, OSError) as exc:
                self._client = None
                task = asyncio.current_task()
                if task is not None and task.cancelling():
                    # The station is closing: the cancel arrived while connecting and came
                    # out as this error (asyncio.timeout and the MQTT client can turn it into
                    # one); retrying would swallow the cancel and the close would never end.
                    raise asyncio.CancelledError from exc
                self.last_error = str(exc) or type(exc).__name__
                failures += 1
                cfg = self._config
                ceiling = min(
                    cfg.backoff_max_s, cfg.backoff_initial_s * 2.0 ** min(failures - 1, 30)
                )
                delay = ceiling / 2.0 + self._rng.uniform(0.0, ceiling / 2.0)
                _log.info("station %s: %s; reconnecting in %.2f s", self.operator, exc, delay)
                await asyncio.sleep(delay)
            else:
                failures = 0

    async def _serve_once(self) -> None:
        topics = self.topics
        async with asyncio.timeout(self._config.connect_timeout_s):
            client = self._client_for()
            await client.__aenter__()
        try:
            await client.subscribe(
                [
                    (topics.recommendations(self.operator), _QOS),
                    (topics.status(self.operator), _QOS),
                    (topics.bridge, _QOS),
                ]
            )
            self._client = client
            self.last_error = ""
            self.connects += 1
            await self._send_all()  # on every (re)connection
            timer = asyncio.create_task(self._resend_periodically())
            try:
                async for message in client.messages:
                    await self._on_message(str(message.topic), message.payload)
            finally:
                timer.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await timer
        finally:
            self._client = None
            with contextlib.suppress(Exception):
                async with asyncio.timeout(self._config.connect_timeout_s):
                    await client.__aexit__(None, None, None)

    async def _resend_periodically(self) -> None:
        while True:
            await asyncio.sleep(self.resend_s)
            await self._send_all()

    async def _on_message(self, topic: str, payload: Any) -> None:
        try:
            msg = json.loads(payload)
            kind = msg["type"]
            key = (str(msg.get("recommendation_id")), int(msg.get("version", -1)))
        except (ValueError, TypeError, KeyError, AttributeError):
            _log.warning("station %s: not a gcs-utm message on %s", self.operator, topic)
            return
        if kind == "recommendation_status":
            self._on_status(msg)
        elif kind == "command_status":
            self._on_command_status(msg)
        elif kind == "bridge_status" and msg.get("online"):
            await self._send_all()  # gcs-utm is subscribed again
        elif kind == "recommendation":
            if key in self._pending:
                await self._send(key)  # asked again: gcs-utm has no answer for it
            else:
                self.recommendations.put_nowait(msg)

    def _on_command_status(self, msg: dict[str, Any]) -> None:
        pending = self._commands.pop(str(msg.get("id")), None)
        if pending is None or pending.acked.done():
            return
        pending.acked.set_result(
            CommandAck(
                request_id=str(msg.get("id")),
                uas=str(msg.get("uas", "")),
                command=str(msg.get("command", "")),
                outcome=str(msg.get("outcome", "")),
                reason=str(msg.get("reason", "")),
                mode=str(msg.get("mode", "")),
            )
        )

    def _on_status(self, msg: dict[str, Any]) -> None:
        answer = msg.get("answer")
        if not isinstance(answer, dict):
            self.statuses.put_nowait(msg)  # a state change, not an acknowledgement
            return
        version = answer.get("version")
        key = (str(msg.get("recommendation_id")), version if isinstance(version, int) else -1)
        pending = self._pending.get(key)
        if pending is None or answer.get("decision") != pending.decision:
            return
        del self._pending[key]
        if not pending.acked.done():
            pending.acked.set_result(
                AnswerAck(
                    recommendation_id=key[0],
                    version=key[1],
                    decision=pending.decision,
                    outcome=str(answer.get("outcome")),
                    state=msg.get("state"),
                    reason=str(msg.get("reason", "")),
                )
            )


__all__ = ["AnswerAck", "CommandAck", "PilotStation"]
