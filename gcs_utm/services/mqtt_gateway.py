"""The USM's MQTT side: connects :class:`adapters.mqtt.bridge.MqttBridge` to the :class:`Usm`.

In (the bridge calls this as its :class:`~adapters.mqtt.bridge.MqttHandler`): positions and
hazards go to the USM; pilot answers go to :meth:`Usm.answer` (the USM matches id + version and
refuses an operator that does not fly the UAS); operator commands (hold, land, rtl, resume) go
to :meth:`Usm.operator_command`, their outcome back on the status topic; flight plans become
operations in the airspace; start/stop change the operation's state.
Out (this is also an :class:`~gcs_utm.services.usm.OperatorPort`, a threat sink and a geofence
listener of the USM): recommendations and their state changes to the operator of the
operation, alerts for new threats, the active geofence set (retained; republished when it
changes and when one of its geofences expires, so a late or remote subscriber never keeps an
expired geofence), and traffic at ``traffic_rate_hz`` from :meth:`MqttGateway.run`.

Invariants:
- the operator of an inbound message is the topic's operator level (set by the codec); an
  answer always reaches the USM with ``source == "mqtt"``;
- an inbound message the USM cannot take raises ``ValueError``: the bridge reports it on the
  errors topics and logs it, nothing crashes;
- every publish only enqueues (the bridge never blocks the USM);
- a cluster member (``arbiter`` set, :mod:`gcs_utm.cluster.inbound`): every instance hears
  the same messages, and only the holder of the region concerned carries out an answer, a
  flight plan, a flight status or an operator command; the others publish nothing, except
  one refusal when no instance holds that region.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from adapters.mqtt import answers as mqtt_answers
from adapters.mqtt.bridge import MqttBridge
from adapters.mqtt.codec import (
    CommandAck,
    FlightPlanSubmission,
    FlightStatusKind,
    FlightStatusReport,
    OperatorCommandRequest,
)
from adapters.mqtt.config import MqttConfig
from gcs_utm.core.monitoring.filing import plan_in_fences
from gcs_utm.flyable import plan_problem
from gcs_utm.geo import LocalFrame
from gcs_utm.messages import HazardReport, PilotAnswer
from gcs_utm.model import (
    Geofence,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    OperationState,
    Recommendation,
    Threat,
    ThreatId,
    ThreatStatus,
    Track,
    TrackId,
)
from gcs_utm.services.airspace import AirspaceError
from gcs_utm.services.usm import Usm

_log = logging.getLogger(__name__)

TrackSource = Callable[[], Mapping[TrackId, Track]]

EXPIRY_SLACK_S = 0.01
"""A geofence is active up to and including its ``end_t_s``: the set is republished this long
after the earliest end, when that geofence is strictly expired."""


@dataclass(frozen=True, slots=True)
class Route:
    """Who handles one inbound message in a cluster: this instance (``here``); else
    ``refusal`` is this instance's answer ("": another instance answers, nothing is
    published here)."""

    here: bool
    refusal: str = ""


HERE = Route(here=True)


class InboundArbiter(Protocol):
    """A cluster member's rule for MQTT input (:mod:`gcs_utm.cluster.inbound`)."""

    async def pilot_answer(self, a: PilotAnswer, operation_id: OperationId | None) -> Route:
        """``operation_id``: the recommendation's operation as this USM knows it."""
        ...

    async def flight_plan(self, s: FlightPlanSubmission) -> Route: ...

    async def flight_status(self, s: FlightStatusReport) -> Route: ...

    async def operator_command(self, c: OperatorCommandRequest, gate_reason: str) -> str:
        """A command refused as another instance's: the refusal to publish ("": none)."""
        ...


class MqttGateway:
    """``gw = MqttGateway(usm, config, tracks=...)``; ``gw.attach()`` wires it into the USM;
    ``await gw.run()`` (in a task group) runs the bridge and the traffic publisher."""

    def __init__(
        self,
        usm: Usm,
        config: MqttConfig,
        *,
        tracks: TrackSource | None = None,
        bridge: MqttBridge | None = None,
        frame: LocalFrame | None = None,
    ) -> None:
        self.usm = usm
        self._frame = frame  # with it, a plan into an active geofence is refused
        self.config = config
        self._tracks = tracks
        self.bridge = bridge or MqttBridge(config, usm.clock, self)
        self._alerted: set[ThreatId] = set()
        self._next_expiry_s: float | None = None  # earliest end of the published set
        self._republish = asyncio.Event()  # the published set changed: re-arm the expiry
        # a cluster member's rule for answers, plans and commands; None: all are ours
        self.arbiter: InboundArbiter | None = None

    def attach(self) -> None:
        """Register as operator port, threat sink and geofence listener of the USM."""
        self.usm.attach_operator(self)
        self.usm.attach_threat_sink(self.on_threats)
        self.usm.attach_geofence_listener(self.on_geofences)

    async def run(self) -> None:
        """The bridge's connection loop and the periodic traffic publisher (until
        cancelled). The current geofence set is published at start (retained)."""
        self.publish_geofences(self.usm.airspace.geofences())
        async with asyncio.TaskGroup() as tg:
            tg.create_task(self.bridge.run(), name="mqtt-bridge")
            tg.create_task(self._expiry_loop(), name="mqtt-geofence-expiry")
            if self._tracks is not None:
                tg.create_task(self._traffic_loop(self._tracks), name="mqtt-traffic")

    async def _expiry_loop(self) -> None:
        """Republish the retained geofence set when its earliest geofence expires (on the
        injected clock); a change of the set in between re-arms the wait."""
        while True:
            self._republish.clear()
            due = self._next_expiry_s
            if due is None:
                await self._republish.wait()
                continue
            delay = max(0.0, due - self.usm.clock.now_s()) + EXPIRY_SLACK_S
            sleep = asyncio.ensure_future(self.usm.clock.sleep(delay))
            changed = asyncio.ensure_future(self._republish.wait())
            try:
                done, _ = await asyncio.wait({sleep, changed}, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for f in (sleep, changed):
                    f.cancel()
            if sleep in done and self._next_expiry_s == due:
                try:
                    self.publish_geofences(self.usm.airspace.geofences())
                except Exception:  # the next change of the set publishes it again
                    _log.exception("mqtt: geofence republication failed")

    async def _traffic_loop(self, tracks: TrackSource) -> None:
        period_s = 1.0 / self.config.traffic_rate_hz
        while True:
            try:
                self.bridge.publish_traffic(list(tracks().values()))
            except Exception:  # one bad snapshot must not stop the traffic feed
                _log.exception("mqtt: traffic publication failed")
            await self.usm.clock.sleep(period_s)

    # ------------------------------------------------------------ MqttHandler (inbound side)

    async def on_measurement(self, m: Measurement) -> None:
        if m.source is MeasurementSource.MQTT and m.operation_id is not None:
            operator = m.link.removeprefix("mqtt:")
            self._own_operation(m.operation_id, operator)
        self.usm.on_measurement(m)

    async def on_hazard(self, h: HazardReport) -> None:
        if h.operation_id is not None and h.operation_id not in self.usm.airspace.operations:
            raise ValueError(f"unknown operation {h.operation_id!r}")
        self.usm.on_hazard(h)

    async def on_pilot_answer(self, a: PilotAnswer) -> mqtt_answers.AnswerOutcome | None:
        """The USM's outcome; in a cluster, None (nothing published) when another instance
        answers, or the arbiter's refusal."""
        if a.source != "mqtt":
            a = dataclasses.replace(a, source="mqtt")
        if self.arbiter is not None:
            known = self.usm.recommendations.get(a.recommendation_id)
            route = await self.arbiter.pilot_answer(
                a, None if known is None else known.rec.operation_id
            )
            if not route.here:
                return None if not route.refusal else self._refused_answer(a, route.refusal)
        outcome = await self.usm.answer(a)
        record = self.usm.recommendations.get(a.recommendation_id)
        return mqtt_answers.AnswerOutcome(
            status=mqtt_answers.AnswerStatus(outcome.status.value),
            recommendation_id=a.recommendation_id,
            version=a.version,
            decision=a.decision,
            reason=outcome.reason,
            state=None if record is None else record.rec.state,
        )

    @staticmethod
    def _refused_answer(a: PilotAnswer, reason: str) -> mqtt_answers.AnswerOutcome:
        return mqtt_answers.AnswerOutcome(
            status=mqtt_answers.AnswerStatus.REFUSED,
            recommendation_id=a.recommendation_id,
            version=a.version,
            decision=a.decision,
            reason=reason,
        )

    async def on_operator_command(self, c: OperatorCommandRequest) -> CommandAck | None:
        """An operator's hold / land / rtl / resume: the USM's one entry point for them
        (refused unless the operator flies the UAS, or is ``admin``). None (nothing
        published) when another cluster instance commands the UAS: it heard the same message
        and answers (gcs_utm.cluster.commands); when no instance holds the UAS's region, the
        arbiter alone answers (gcs_utm.cluster.inbound)."""
        result = await self.usm.operator_command(
            c.uas, c.command, operator=c.operator, source="mqtt", request_id=c.request_id
        )
        if result.elsewhere:
            arbiter = self.arbiter
            reason = "" if arbiter is None else await arbiter.operator_command(c, result.reason)
            if not reason:
                return None
            result = dataclasses.replace(result, reason=reason)
        return CommandAck(
            request_id=c.request_id,
            uas=result.uas,
            command=result.command,
            outcome=result.outcome.value,
            reason=result.reason,
            mode=result.mode,
        )

    async def on_flight_plan(self, s: FlightPlanSubmission) -> None:
        """File the plan as an operation; raise ValueError to refuse it. In a cluster, only
        the holder of its departure's region files it; another instance returns (nothing
        published) or, as the arbiter of a region nobody holds, refuses it."""
        if self.arbiter is not None:
            route = await self.arbiter.flight_plan(s)
            if route.refusal:
                raise ValueError(route.refusal)
            if not route.here:
                return
        airspace = self.usm.airspace
        if s.operation_id in airspace.operations:
            raise ValueError(f"operation {s.operation_id!r} already exists")
        cfg = self.usm.config
        op = s.to_operation(
            default_priority=cfg.default_priority,
            default_cruise_speed_mps=cfg.default_cruise_speed_mps,
            default_flight_geometry_m=cfg.default_flight_geometry_m,
            default_operational_volume_m=cfg.default_operational_volume_m,
        )
        problem = plan_problem(op)
        if problem is not None:  # below a fixed wing's minimum airspeed, or too steep
            raise ValueError(problem)
        if self._frame is not None:
            found = plan_in_fences(op.plan, op, airspace.geofences(), self._frame)
            if found:
                raise ValueError("; ".join(f.message() for f in found))
        airspace.add_operation(op)
        self.usm.log_event("operation", f"{op.id} filed over MQTT by {s.operator}")

    async def on_flight_status(self, s: FlightStatusReport) -> None:
        """Start or stop an operation (in a cluster: by its owner only, as a plan is)."""
        if self.arbiter is not None:
            route = await self.arbiter.flight_status(s)
            if route.refusal:
                raise ValueError(route.refusal)
            if not route.here:
                return
        op = self._own_operation(s.operation_id, s.operator)
        if s.plan_version is not None and s.plan_version != op.plan.version:
            raise ValueError(
                f"plan version {s.plan_version} is not the current version {op.plan.version}"
            )
        if s.status is FlightStatusKind.START:
            if op.state not in (OperationState.PLANNED, OperationState.ACTIVE):
                raise ValueError(f"operation {op.id} is {op.state.value}: cannot start")
            state = OperationState.ACTIVE
        else:
            state = OperationState.ENDED
        self.usm.airspace.set_state(op.id, state)
        self.usm.log_event("operation", f"{op.id} {s.status.value} by {s.operator}")

    def _own_operation(self, op_id: OperationId, operator: str) -> Operation:
        try:
            op = self.usm.airspace.operation(op_id)
        except AirspaceError as exc:
            raise ValueError(str(exc)) from None
        if operator not in (op.operator, "admin"):
            raise ValueError(f"operator {operator!r} does not fly {op_id}")
        return op

    # ------------------------------------------------------------- OperatorPort (outbound)

    def _operator_of(self, rec: Recommendation) -> str | None:
        try:
            return self.usm.airspace.operation(rec.operation_id).operator
        except AirspaceError:
            _log.warning("mqtt: recommendation %s for unknown operation", rec.id)
            return None

    async def present(self, rec: Recommendation) -> None:
        operator = self._operator_of(rec)
        if operator is not None:
            self.bridge.publish_recommendation(rec, operator)

    async def update(self, rec: Recommendation) -> None:
        operator = self._operator_of(rec)
        if operator is not None:
            self.bridge.publish_recommendation_status(rec, operator)

    # ------------------------------------------------------------- threats and geofences

    async def on_threats(self, threats: list[Threat]) -> None:
        """Threat sink: one alert per new threat, to the operators of the UAS involved (or
        to everyone for an airspace-wide threat)."""
        ops = self.usm.airspace.operations
        for t in threats:
            if t.status is ThreatStatus.CLOSED:
                self._alerted.discard(t.id)
                continue
            if t.id in self._alerted:
                continue
            self._alerted.add(t.id)
            operators = sorted({ops[u].operator for u in t.uas_ids if u in ops})
            self.bridge.publish_alert(t, operators)

    async def on_geofences(self, geofences: Sequence[Geofence]) -> None:
        """Geofence listener: the active set, retained."""
        self.publish_geofences(geofences)

    def publish_geofences(self, geofences: Sequence[Geofence]) -> None:
        """Publish the geofences not expired now (retained) and arm the republication at the
        earliest end among them."""
        now = self.usm.clock.now_s()
        active = [g for g in geofences if g.end_t_s is None or g.end_t_s >= now]
        self.bridge.publish_geofences(active)
        ends = [g.end_t_s for g in active if g.end_t_s is not None]
        self._next_expiry_s = min(ends) if ends else None
        self._republish.set()
