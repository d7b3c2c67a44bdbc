"""The MQTT bridge of the USM: one aiomqtt client, reconnecting, with a bounded outgoing queue.

Role: translate between the broker and the USM's :class:`MqttHandler`; decide nothing about
the airspace. The USM decides what an answer means (:meth:`gcs_utm.services.usm.Usm.answer`)
and the bridge publishes that outcome (:class:`~adapters.mqtt.answers.AnswerOutcome`) on the
operator's status topic.

Invariants and policies:

- The client is an async context manager per connection; :meth:`MqttBridge.run` loops
  connect -> serve -> back off. Backoff doubles from ``backoff_initial_s`` up to
  ``backoff_max_s`` with equal jitter (half fixed, half random) so a fleet of stations
  restarted together does not reconnect in lock step. Backoff is wall time (asyncio), not
  the injected clock: it is about the network, and a manual test clock must not make it spin.
- Session: MQTT 5, fixed ``client_id``, clean start off and a session expiry interval
  (``session_expiry_s``), subscriptions at QoS 1: QoS 1 answers sent while the UTM is away
  are kept by the broker (in memory: no broker persistence needed) and delivered on
  reconnect. A broker restart without persistence (mosquitto's default) loses that session:
  on every reconnect the bridge re-publishes the recommendations still waiting for an answer
  (before their deadline) and the retained ``online`` status (after subscribing), and every
  answer's outcome is published on the operator's status topic: a station keeping its answer
  until that acknowledgement re-sends it then (:mod:`adapters.mqtt.station`); the USM takes
  a repeated answer as a duplicate.
- Outgoing queue (``queue_max``): every ``publish_*`` call only enqueues (never blocks the
  caller). A message leaves the queue only after the broker acknowledged it (QoS 1) or took
  it (QoS 0), so messages produced while the broker is down are sent after reconnect
  (at-least-once: one in flight at the moment of a disconnect may be sent twice; every
  outgoing message is idempotent for the receiver). State topics (geofences, traffic, bridge
  status) are latest-wins: a newer message replaces the queued one. When full, the oldest
  message is dropped, counted in ``stats.dropped`` and logged.
- Inbound: a malformed message, schema violation, unknown operation or handler failure gives
  one ``error`` message on ``<prefix>/errors`` (and on the sender operator's ``errors``
  topic) and one log line; nothing propagates into the event loop.
- Time stamps of outgoing messages come from the injected :class:`~gcs_utm.clock.Clock`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Protocol, cast

import aiomqtt

from adapters.mqtt.answers import AnswerOutcome
from adapters.mqtt.client import session_client
from adapters.mqtt.codec import (
    CommandAck,
    FlightPlanSubmission,
    FlightStatusReport,
    Inbound,
    MqttMessageError,
    OperatorCommandRequest,
    RpaState,
    Topics,
    decode,
    encode_alert,
    encode_bridge_status,
    encode_command_status,
    encode_error,
    encode_geofence_event,
    encode_geofences,
    encode_recommendation,
    encode_recommendation_status,
    encode_traffic,
    geofence_json,
)
from adapters.mqtt.config import MqttConfig
from gcs_utm.clock import Clock
from gcs_utm.messages import HazardReport, PilotAnswer
from gcs_utm.model import (
    Geofence,
    GeofenceId,
    Measurement,
    ModelError,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    Track,
)

_log = logging.getLogger(__name__)

QOS_AT_MOST_ONCE = 0
QOS_AT_LEAST_ONCE = 1


class MqttHandler(Protocol):
    """What the USM implements to receive MQTT input. All methods are coroutines; an
    exception raised by one is reported as an error message and logged, never re-raised."""

    async def on_measurement(self, m: Measurement) -> None:
        """A position from an RPA state message (source MQTT) or an ADS-B report (ADSB)."""
        ...

    async def on_hazard(self, h: HazardReport) -> None:
        """A stakeholder alert (with ``area``) or a GNSS jamming/spoofing/integrity report."""
        ...

    async def on_pilot_answer(self, a: PilotAnswer) -> AnswerOutcome | None:
        """An answer (``a.operator`` is the topic's operator). Return what became of it; the
        bridge publishes the outcome on the operator's status topic. None: another service
        instance answers it (nothing is published here)."""
        ...

    async def on_flight_plan(self, s: FlightPlanSubmission) -> None:
        """A plan submission; raise ``ValueError`` (e.g. ModelError) to refuse it: the reason
        goes to the operator's errors topic."""
        ...

    async def on_flight_status(self, s: FlightStatusReport) -> None: ...

    async def on_operator_command(self, c: OperatorCommandRequest) -> CommandAck | None:
        """An operator's hold / land / rtl / resume (``c.operator`` is the topic's operator).
        Return what became of it; the bridge publishes it on the operator's status topic.
        None: another service instance answers it (nothing is published here)."""
        ...


@dataclass(slots=True)
class BridgeStats:
    """Counters (monotonic over the bridge's life)."""

    received: int = 0
    rejected: int = 0
    handler_errors: int = 0
    published: int = 0
    dropped: int = 0
    connects: int = 0
    connection_losses: int = 0


@dataclass(frozen=True, slots=True)
class _Outgoing:
    topic: str
    payload: bytes
    qos: int
    retain: bool
    latest_wins: bool


class MqttBridge:
    """``async with MqttBridge(config, clock, handler) as bridge:`` runs the connection loop
    in a background task until the block exits; or ``await bridge.run()`` in a task group."""

    def __init__(
        self,
        config: MqttConfig,
        clock: Clock,
        handler: MqttHandler,
        *,
        rng: random.Random | None = None,
    ) -> None:
        self._config = config
        self._clock = clock
        self._handler = handler
        self._rng = rng or random.Random()
        self.topics = Topics(config.topic_prefix)
        self.stats = BridgeStats()
        self._queue: deque[_Outgoing] = deque()
        self._wakeup = asyncio.Event()
        # one inbox for the bridge's life, handed to every aiomqtt client as its message
        # queue: a message paho has acknowledged to the broker but we have not handled yet
        # survives the connection that received it (else a disconnect would lose an answer)
        self._inbox: asyncio.Queue[aiomqtt.Message] = asyncio.Queue(maxsize=config.queue_max)
        self._connected = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._abandoned: set[asyncio.Task[None]] = set()
        self._commands: set[asyncio.Task[None]] = set()  # operator commands being carried out
        self._rec_operator: dict[RecommendationId, str] = {}
        # recommendations still waiting for an answer: re-published on every reconnect
        self._outstanding: dict[RecommendationId, tuple[Recommendation, str]] = {}
        self._published_geofences: dict[GeofenceId, Geofence] = {}
        self._last_traffic_t_s: float | None = None

    # ---------------------------------------------------------------------------- lifecycle

    async def __aenter__(self) -> MqttBridge:
        self._task = asyncio.create_task(self.run(), name="mqtt-bridge")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    async def wait_connected(self, timeout_s: float | None = None) -> None:
        """Wait until connected and subscribed (raises TimeoutError)."""
        await asyncio.wait_for(self._connected.wait(), timeout_s)

    @property
    def pending(self) -> int:
        """Outgoing messages not yet acknowledged by the broker."""
        return len(self._queue)

    async def flush(self, timeout_s: float = 10.0) -> None:
        """Wait until the outgoing queue is empty (raises TimeoutError)."""
        async with asyncio.timeout(timeout_s):
            while self._queue:
                await asyncio.sleep(0.01)

    def _client(self) -> aiomqtt.Client:
        cfg = self._config
        return session_client(
            cfg,
            cfg.client_id,
            max_queued_incoming_messages=cfg.queue_max,
            queue_type=self._inbox_factory(),
            will=aiomqtt.Will(
                self.topics.bridge,
                encode_bridge_status(False, None),
                qos=QOS_AT_LEAST_ONCE,
                retain=True,
            ),
        )

    def _inbox_factory(self) -> type[asyncio.Queue[aiomqtt.Message]]:
        inbox = self._inbox

        def factory(maxsize: int = 0) -> asyncio.Queue[aiomqtt.Message]:
            return inbox

        return cast("type[asyncio.Queue[aiomqtt.Message]]", factory)

    async def _drain_inbox(self) -> None:
        """Handle messages received by a connection that has ended."""
        while not self._inbox.empty():
            await self._handle_message(self._inbox.get_nowait())

    def backoff_s(self, failures: int) -> float:
        """Delay before reconnect attempt after ``failures`` consecutive failures (>= 1)."""
        cfg = self._config
        ceiling = min(cfg.backoff_max_s, cfg.backoff_initial_s * 2.0 ** max(0, failures - 1))
        return ceiling / 2.0 + self._rng.uniform(0.0, ceiling / 2.0)

    async def run(self) -> None:
        """Connect, serve, reconnect forever (until cancelled; operator commands still being
        carried out are cancelled with it)."""
        try:
            await self._run()
        finally:
            for task in list(self._commands):
                task.cancel()

    async def _run(self) -> None:
        failures = 0
        while True:
            connects_before = self.stats.connects
            try:
                await self._serve_once()
            except (aiomqtt.MqttError, TimeoutError, OSError) as exc:
                self._connected.clear()
                await self._drain_inbox()
                if self.stats.connects > connects_before:
                    self.stats.connection_losses += 1
                    failures = 0
                failures += 1
                delay = self.backoff_s(failures)
                _log.warning(
                    "mqtt %s:%d: %s; reconnecting in %.2f s (%d queued)",
                    self._config.host,
                    self._config.port,
                    exc,
                    delay,
                    len(self._queue),
                )
                await asyncio.sleep(delay)

    async def _serve_once(self) -> None:
        client = self._client()
        try:
            # paho's connect can stall when the broker vanishes mid-handshake: bound it
            async with asyncio.timeout(self._config.connect_timeout_s):
                await client.__aenter__()
        except TimeoutError as exc:
            raise aiomqtt.MqttError("connect timed out") from exc
        try:
            await self._serve_connected(client)
        finally:
            with contextlib.suppress(Exception):
                async with asyncio.timeout(self._config.connect_timeout_s):
                    await client.__aexit__(None, None, None)

    async def _serve_connected(self, client: aiomqtt.Client) -> None:
        async with asyncio.timeout(self._config.connect_timeout_s):
            await client.subscribe([(f, QOS_AT_LEAST_ONCE) for f in self.topics.subscriptions()])
        self._enqueue(
            self.topics.bridge,
            encode_bridge_status(True, self._clock.now_s()),
            qos=QOS_AT_LEAST_ONCE,
            retain=True,
            latest_wins=True,
        )
        if self.stats.connects:
            self._rerequest()
        self.stats.connects += 1
        self._connected.set()
        _log.info("mqtt connected to %s:%d", self._config.host, self._config.port)
        sender = asyncio.create_task(self._sender(client), name="mqtt-sender")
        receiver = asyncio.create_task(self._receiver(client), name="mqtt-receiver")
        try:
            done, _ = await asyncio.wait({sender, receiver}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            self._connected.clear()
            for task in (sender, receiver):
                task.cancel()
            # aiomqtt's publish can swallow a cancellation (asyncio.wait_for race on 3.11)
            # and then wait on a dead client: never wait for it unboundedly
            _, stuck = await asyncio.wait({sender, receiver}, timeout=1.0)
            for task in stuck:
                _log.warning("mqtt: %s did not stop; abandoned", task.get_name())
                self._abandoned.add(task)
                task.add_done_callback(self._abandoned.discard)
        for task in done:
            if not task.cancelled():
                task.result()  # raises the MqttError that ended the connection
        raise aiomqtt.MqttError("connection tasks ended")

    # ------------------------------------------------------------------------------ sending

    async def _sender(self, client: aiomqtt.Client) -> None:
        while self._connected.is_set():
            while not self._queue:
                self._wakeup.clear()
                await self._wakeup.wait()
            if not self._connected.is_set():
                return  # an abandoned sender of an ended connection
            item = self._queue[0]
            await client.publish(
                item.topic,
                item.payload,
                qos=item.qos,
                retain=item.retain,
                timeout=self._config.publish_timeout_s,
            )
            # the head may have been replaced (latest-wins) or dropped while in flight
            if self._queue and self._queue[0] is item:
                self._queue.popleft()
            self.stats.published += 1
            _log.debug("mqtt: published %s (%d pending)", item.topic, len(self._queue))

    def _enqueue(
        self,
        topic: str,
        payload: bytes,
        *,
        qos: int,
        retain: bool = False,
        latest_wins: bool = False,
    ) -> None:
        if latest_wins:
            for i, queued in enumerate(self._queue):
                if queued.topic == topic and i > 0:
                    del self._queue[i]
                    break
        if len(self._queue) >= self._config.queue_max:
            dropped = self._queue.popleft()
            self.stats.dropped += 1
            _log.warning(
                "mqtt outgoing queue full (%d): dropped the oldest message on %s (%d dropped)",
                self._config.queue_max,
                dropped.topic,
                self.stats.dropped,
            )
        self._queue.append(_Outgoing(topic, payload, qos, retain, latest_wins))
        self._wakeup.set()

    def publish_alert(self, threat: Threat, operators: Sequence[str] = ()) -> None:
        """An alert to the given operators' ``alerts`` topics, or to ``<prefix>/alerts``
        (everyone) when no operator is given. QoS 1."""
        payload = encode_alert(threat)
        topics = [self.topics.alerts_for(op) for op in operators] or [self.topics.alerts]
        for topic in topics:
            self._enqueue(topic, payload, qos=QOS_AT_LEAST_ONCE)

    def publish_recommendation(self, rec: Recommendation, operator: str) -> None:
        """An alternative plan / command proposal to ``operator`` (QoS 1). Remembers the
        operator for :meth:`publish_recommendation_status`, and the recommendation until it
        is answered, ends or passes its deadline (re-published on every reconnect)."""
        topic = self.topics.recommendations(operator)
        self._rec_operator[rec.id] = operator
        if rec.state is RecommendationState.PROPOSED:
            self._outstanding[rec.id] = (rec, operator)
        self._enqueue(topic, encode_recommendation(rec), qos=QOS_AT_LEAST_ONCE)

    @property
    def outstanding(self) -> list[RecommendationId]:
        """Recommendations re-published on the next reconnect."""
        return list(self._outstanding)

    def _rerequest(self) -> None:
        """Re-publish the recommendations still waiting for an answer: a broker restarted
        without persistence lost our session, and with it any answer sent meanwhile."""
        now = self._clock.now_s()
        for rec_id, (rec, operator) in list(self._outstanding.items()):
            if rec.deadline_t_s < now:
                del self._outstanding[rec_id]
                continue
            topic = self.topics.recommendations(operator)
            payload = encode_recommendation(rec)
            if any(q.topic == topic and q.payload == payload for q in self._queue):
                continue  # never sent yet: it goes out anyway
            _log.info("mqtt: re-requesting an answer to %s v%d", rec.id, rec.version)
            self._enqueue(topic, payload, qos=QOS_AT_LEAST_ONCE)

    def publish_recommendation_status(
        self, rec: Recommendation, operator: str | None = None
    ) -> None:
        """The state of ``rec`` (accepted, uploading, applied, expired...) on its operator's
        status topic (QoS 1). Raises ValueError when the operator is unknown."""
        op = operator or self._rec_operator.get(rec.id)
        if op is None:
            raise ValueError(f"recommendation {rec.id}: operator unknown; pass operator=")
        waiting = self._outstanding.get(rec.id)
        if waiting is not None and (
            rec.state is not RecommendationState.PROPOSED or waiting[0].version < rec.version
        ):
            del self._outstanding[rec.id]
        payload = encode_recommendation_status(
            recommendation_id=rec.id,
            version=rec.version,
            t_s=self._clock.now_s(),
            state=rec.state,
            reason=rec.reason,
        )
        self._enqueue(self.topics.status(op), payload, qos=QOS_AT_LEAST_ONCE)

    def publish_answer_outcome(self, outcome: AnswerOutcome, operator: str) -> None:
        """The outcome of one pilot answer on ``operator``'s status topic (QoS 1)."""
        if outcome.state not in (None, RecommendationState.PROPOSED):
            waiting = self._outstanding.get(outcome.recommendation_id)
            if waiting is not None and waiting[0].version == outcome.version:
                del self._outstanding[outcome.recommendation_id]
        payload = encode_recommendation_status(
            recommendation_id=outcome.recommendation_id,
            version=outcome.version,
            t_s=self._clock.now_s(),
            state=outcome.state,
            reason=outcome.reason,
            answer={
                "outcome": outcome.status.value,
                "decision": outcome.decision.value,
                "version": outcome.version,
            },
        )
        self._enqueue(self.topics.status(operator), payload, qos=QOS_AT_LEAST_ONCE)

    async def _operator_command(self, topic: str, c: OperatorCommandRequest) -> None:
        """Carry out one operator command and publish its outcome; report, never raise."""
        try:
            ack = await self._handler.on_operator_command(c)
        except ValueError as exc:
            self.stats.rejected += 1
            self.publish_error(topic, "", f"refused: {exc}")
            return
        except Exception as exc:
            self.stats.handler_errors += 1
            _log.exception("mqtt: operator command from %s failed", c.operator)
            self.publish_error(topic, "", f"internal error while handling: {type(exc).__name__}")
            return
        if ack is None:
            _log.debug(
                "mqtt: command %s %s id %s: answered elsewhere", c.command, c.uas, c.request_id
            )
            return
        _log.info(
            "mqtt: command %s %s id %s from %s: %s %s",
            c.command,
            c.uas,
            c.request_id,
            c.operator,
            ack.outcome,
            ack.reason,
        )
        self.publish_command_status(ack, c.operator)

    def publish_command_status(self, ack: CommandAck, operator: str) -> None:
        """The outcome of one operator command on ``operator``'s status topic (QoS 1)."""
        payload = encode_command_status(
            request_id=ack.request_id,
            uas=ack.uas,
            command=ack.command,
            t_s=self._clock.now_s(),
            outcome=ack.outcome,
            reason=ack.reason,
            mode=ack.mode,
        )
        self._enqueue(self.topics.status(operator), payload, qos=QOS_AT_LEAST_ONCE)

    def publish_geofences(self, active: Iterable[Geofence]) -> None:
        """The complete active set, retained on ``<prefix>/geofences`` (a late subscriber
        gets it at once), plus one ``geofence_event`` per created/changed/removed geofence on
        ``<prefix>/geofences/events`` (QoS 1). Publishing an unchanged set sends only the
        retained state."""
        t_s = self._clock.now_s()
        current = {g.id: g for g in active}
        self._enqueue(
            self.topics.geofences,
            encode_geofences(current.values(), t_s),
            qos=QOS_AT_LEAST_ONCE,
            retain=True,
            latest_wins=True,
        )
        old = self._published_geofences
        for gid, g in current.items():
            if gid not in old or geofence_json(old[gid]) != geofence_json(g):
                self._enqueue(
                    self.topics.geofence_events,
                    encode_geofence_event("created", g, t_s),
                    qos=QOS_AT_LEAST_ONCE,
                )
        for gid, g in old.items():
            if gid not in current:
                self._enqueue(
                    self.topics.geofence_events,
                    encode_geofence_event("removed", g, t_s),
                    qos=QOS_AT_LEAST_ONCE,
                )
        self._published_geofences = current

    def publish_traffic(self, tracks: Iterable[Track]) -> bool:
        """Traffic information on ``<prefix>/traffic`` (QoS 0, latest-wins). At most
        ``traffic_rate_hz`` per clock second: returns False (nothing sent) when called sooner;
        the caller's next periodic call carries the newer state."""
        t_s = self._clock.now_s()
        min_gap_s = 1.0 / self._config.traffic_rate_hz
        if self._last_traffic_t_s is not None and t_s - self._last_traffic_t_s < min_gap_s:
            return False
        self._last_traffic_t_s = t_s
        self._enqueue(
            self.topics.traffic,
            encode_traffic(tracks, t_s),
            qos=QOS_AT_MOST_ONCE,
            latest_wins=True,
        )
        return True

    def publish_error(self, topic: str, field: str, reason: str) -> None:
        """An error about a message received on ``topic``: on ``<prefix>/errors`` and, when
        ``topic`` belongs to an operator, on that operator's ``errors`` topic (QoS 1)."""
        payload = encode_error(topic, field, reason, self._clock.now_s())
        self._enqueue(self.topics.errors, payload, qos=QOS_AT_LEAST_ONCE)
        operator = self.topics.operator_of(topic)
        if operator is not None:
            self._enqueue(self.topics.errors_for(operator), payload, qos=QOS_AT_LEAST_ONCE)

    # ---------------------------------------------------------------------------- receiving

    async def _receiver(self, client: aiomqtt.Client) -> None:
        async for message in client.messages:
            # shielded: a connection loss must not cancel an answer half-handled
            await asyncio.shield(self._handle_message(message))

    async def _handle_message(self, message: aiomqtt.Message) -> None:
        payload = message.payload
        if not isinstance(payload, bytes | bytearray | str):
            payload = b"" if payload is None else str(payload).encode()
        await self.handle(str(message.topic), payload)

    async def handle(self, topic: str, payload: bytes | bytearray | str) -> None:
        """Decode and dispatch one inbound message; report, never raise."""
        if self.topics.is_own_output(topic):
            return  # our own output echoed by the operators/+/+ subscription
        self.stats.received += 1
        try:
            msg = decode(self.topics, topic, payload, self._clock.now_s())
        except MqttMessageError as exc:
            self.stats.rejected += 1
            _log.warning("mqtt: rejected message: %s", exc)
            self.publish_error(topic, exc.field, exc.reason)
            return
        try:
            await self._dispatch(topic, msg)
        except (ModelError, ValueError) as exc:
            self.stats.rejected += 1
            field = exc.field_name if isinstance(exc, ModelError) else ""
            _log.warning("mqtt: %s refused by the USM: %s", topic, exc)
            self.publish_error(topic, field, f"refused: {exc}")
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self.stats.handler_errors += 1
            _log.exception("mqtt: handler failed on a message from %s", topic)
            self.publish_error(topic, "", f"internal error while handling: {type(exc).__name__}")

    async def _dispatch(
        self,
        topic: str,
        msg: Inbound,
    ) -> None:
        h = self._handler
        if isinstance(msg, RpaState):
            await h.on_measurement(msg.measurement)
            for hazard in msg.hazards:
                await h.on_hazard(hazard)
        elif isinstance(msg, Measurement):
            await h.on_measurement(msg)
        elif isinstance(msg, HazardReport):
            await h.on_hazard(msg)
        elif isinstance(msg, PilotAnswer):
            outcome = await h.on_pilot_answer(msg)
            if outcome is None:
                _log.debug(
                    "mqtt: answer %s v%d: answered elsewhere", msg.recommendation_id, msg.version
                )
                return
            _log.info(
                "mqtt: answer %s v%d %s from %s: %s %s",
                msg.recommendation_id,
                msg.version,
                msg.decision.value,
                msg.operator,
                outcome.status.value,
                outcome.reason,
            )
            self.publish_answer_outcome(outcome, msg.operator)
        elif isinstance(msg, OperatorCommandRequest):
            # in a task: a command waits for the vehicle, the next message must not
            task = asyncio.create_task(self._operator_command(topic, msg))
            self._commands.add(task)
            task.add_done_callback(self._commands.discard)
        elif isinstance(msg, FlightPlanSubmission):
            await h.on_flight_plan(msg)
        else:
            await h.on_flight_status(msg)
