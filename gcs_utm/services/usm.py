"""U-space Service Manager (paper §4.1): the only door between the UTM core and the world.

In: measurements, vehicle status, hazards and new vehicles from the MAVLink hub (and ADS-B,
tlog, MQTT through the same methods); threats from Monitoring; decisions from Emergency
Management; pilot answers from the dashboard or MQTT.
Out: recommendations to the operator(s); accepted plans uploaded to the vehicle as a MAVLink
mission (verified by readback) and then installed as a new plan version; commands; new
geofences into the airspace; everything recorded.

The recommendation and answer lifecycle (proposals, answers, uploads, final states) is a part
the USM holds (:attr:`Usm.lifecycle`, :mod:`gcs_utm.services.recommendations`); its
invariants are stated there. Nothing is dropped silently: every outcome goes to the record
callback and the event log.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections import deque
from collections.abc import Awaitable, Callable, Collection, Sequence
from dataclasses import dataclass, replace

from adapters.mavlink.senders import idle_keys, over_cap_keys
from gcs_utm.clock import Clock
from gcs_utm.messages import (
    FlightMode,
    HazardReport,
    LinkHealth,
    PilotAnswer,
    VehicleStatus,
)
from gcs_utm.model import (
    LANE_STRIDE,
    AuditEntry,
    Command,
    CommandKind,
    Geofence,
    GeofenceId,
    LaneSource,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    OperationState,
    PositionLane,
    Recommendation,
    RecommendationId,
    SysId,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
)
from gcs_utm.ratelog import RateLimitedLog
from gcs_utm.services.airspace import Airspace, AirspaceError
from gcs_utm.services.flight_state import FlightState, Phase
from gcs_utm.services.operator_commands import CommandResult, OperatorCommands, VehicleView
from gcs_utm.services.recommendations import (
    AnswerOutcome,
    AnswerStatus,
    CommandOutcome,
    LifecycleHooks,
    OperatorPort,
    RecommendationLifecycle,
    RecommendationRecord,
    UploadOutcome,
    VehiclePort,
    resume_index,
)
from gcs_utm.services.telemetry_stats import (
    LaneStats,
    SourceStats,
    TelemetryStats,
    latest_per_sys_id,
)
from gcs_utm.services.threat_lifecycle import Evidence, ThreatCloser
from gcs_utm.services.usm_config import UsmConfig
from gcs_utm.services.vehicle_ops import VehicleOps, VehicleOpsSettings

__all__ = [
    "AnswerOutcome",
    "AnswerStatus",
    "CommandOutcome",
    "OperatorPort",
    "RecommendationRecord",
    "TelemetryStats",
    "UploadOutcome",
    "Usm",
    "UsmConfig",
    "VehiclePort",
    "resume_index",
]

_log = logging.getLogger(__name__)
_TASK_ERROR_INTERVAL_S = 10.0  # one line per failing task kind in this time (ratelog)

_VEHICLE_HAZARDS = frozenset(
    {
        ThreatKind.GNSS_DEGRADATION,
        ThreatKind.JAMMING_ATTACK,
        ThreatKind.SPOOFING_ATTACK,
        ThreatKind.LACK_OF_BATTERY,
        ThreatKind.TECHNICAL_FAILURE,
        ThreatKind.COMMUNICATION_FAILURE,
        ThreatKind.REMOTE_ID_MISMATCH,  # its broadcast or its filing: the pilot's checks
    }
)
"""A vehicle's own hazards: on the ground they are its pre-flight findings, not threats."""


@dataclass(frozen=True, slots=True, kw_only=True)
class UsmEvent:
    t_s: float
    kind: str
    text: str


class Usm:
    """The U-space Service Manager. Construct it, then ``attach_*`` the parts."""

    def __init__(
        self,
        airspace: Airspace,
        clock: Clock,
        *,
        config: UsmConfig | None = None,
        record: Callable[[object], None] | None = None,
        position_lane: bool = True,
        id_prefix: str = "",
        ground_elevation_amsl_m: float | None = None,
    ) -> None:
        """``ground_elevation_amsl_m``: the airspace's ground, to warn about vehicles whose
        home is far from it (None: no warning)."""
        self.airspace = airspace
        # prefixes hazard threat ids (the store life's ``E<epoch>-``): unique across restarts
        self.id_prefix = id_prefix
        self.clock = clock
        self.config = config or UsmConfig()
        self._record = record or (lambda _obj: None)
        self._vehicles: VehiclePort | None = None
        self._measurement_sinks: list[Callable[[Measurement], None]] = []
        self._plain_sinks: list[Callable[[Measurement], None]] = []  # (without a lane sink)
        # Telemetry positions in columns (see on_position_lane): the MAVLink hub appends to
        # it instead of calling on_measurement per report.
        self.position_lane = PositionLane() if position_lane else None
        self._lane_sinks: list[Callable[[list[float], Sequence[LaneSource]], None]] = []
        self._lane_stats = LaneStats()  # per lane source index
        self._lane_unknown: list[bool] = []  # per index: no operation flies its system id
        self._lane_any_unknown = False
        self._lane_version = -1  # the airspace version of _lane_unknown
        self._threat_sinks: list[Callable[[list[Threat]], Awaitable[None]]] = []
        self._answer_sinks: list[Callable[[Recommendation, bool], Awaitable[None]]] = []
        self._operators: list[OperatorPort] = []
        self._geofence_listeners: list[Callable[[Sequence[Geofence]], Awaitable[None]]] = []
        # per vehicle, as health: (system id, where it was first heard)
        self.statuses: dict[tuple[SysId, str], VehicleStatus] = {}
        self.flight: dict[tuple[SysId, str], FlightState] = {}
        self._flight_by_sys_id: dict[SysId, FlightState] = {}
        # per vehicle: (system id, where it was first heard), see LinkHealth.vehicle
        self.health: dict[tuple[SysId, str], LinkHealth] = {}
        self.threats: dict[ThreatId, Threat] = {}
        self.threat_log: deque[Threat] = deque(maxlen=self.config.threat_log_size)
        self._telemetry: dict[str, TelemetryStats] = {}
        self._sources: dict[tuple[object, ...], SourceStats] = {}
        self.events: deque[UsmEvent] = deque(maxlen=self.config.event_log_size)
        self._hazard_seen: dict[tuple[ThreatKind, str], float] = {}
        self._hazard_sweep_t_s = float("-inf")
        self._hazard_seq = itertools.count(1)
        self._hazard_threats: dict[tuple[ThreatKind, str], ThreatId] = {}  # open, per key
        self.threat_closer = ThreatCloser(
            Evidence(
                operation=self.operation_or_none,
                status=lambda sys_id: self.statuses_by_sys_id().get(sys_id),
                health=lambda sys_id: self.health_by_sys_id().get(sys_id),
            ),
            self._close_threat,
            clear_s=self.config.threat_clear_s,
            quiet_s=self.config.hazard_cooldown_s,
        )
        self._tasks: set[asyncio.Task[None]] = set()
        self._task_errors = RateLimitedLog(_log, _TASK_ERROR_INTERVAL_S, max_causes=64)
        # a sender toggling armed or rebooting on every frame must not flood log and events
        self._transitions = RateLimitedLog(
            _log, _TASK_ERROR_INTERVAL_S, now=self.clock.now_s, max_causes=256
        )
        self.counters: dict[str, int] = {
            "measurements": 0,
            "unknown_vehicle_measurements": 0,
            "hazards": 0,
            "hazards_coalesced": 0,
            "hazards_on_ground": 0,
            "answers_refused": 0,
            "uploads_ok": 0,
            "uploads_failed": 0,
            "adsb_sources_evicted": 0,
            "hazard_keys_evicted": 0,
            "threat_log_dropped": 0,
        }
        cfg = self.config
        self.vehicle_ops = VehicleOps(
            airspace,
            clock,
            VehicleOpsSettings(
                priority=cfg.default_priority,
                flight_geometry_m=cfg.default_flight_geometry_m,
                operational_volume_m=cfg.default_operational_volume_m,
                cruise_speed_mps=cfg.default_cruise_speed_mps,
                fixed_wing_cruise_speed_mps=cfg.default_fixed_wing_cruise_speed_mps,
                ground_warning_m=cfg.ground_warning_m,
                home_tolerance_m=cfg.home_tolerance_m,
                ground_elevation_amsl_m=ground_elevation_amsl_m,
            ),
            log_event=self.log_event,
            spawn=self._spawn,
        )
        # proposals, answers and uploads; ``recommendations`` is its table
        self.lifecycle = RecommendationLifecycle(
            airspace,
            clock,
            upload_attempts=cfg.upload_attempts,
            threats=self.threats,
            counters=self.counters,
            operators=self._operators,
            answer_sinks=self._answer_sinks,
            hooks=LifecycleHooks(
                vehicles=lambda: self._vehicles,
                expect_upload=self.vehicle_ops.expect_upload,
                execute_command=lambda command, reason: self.execute_command(
                    command, reason=reason
                ),
                record=self._record,
                log_event=self.log_event,
                spawn=self._spawn,
            ),
        )
        self.recommendations: dict[RecommendationId, RecommendationRecord] = (
            self.lifecycle.recommendations
        )
        # the operator's hold / land / rtl / resume (docs/usm.md, "Operator commands")
        self.operator_commands = OperatorCommands(
            airspace,
            clock,
            VehicleView(
                statuses=self.statuses_by_sys_id,
                health=self.health_by_sys_id,
                flight=self._flight_by_sys_id.get,
                linked=lambda: self._vehicles is not None,
            ),
            execute=lambda command, reason: self.execute_command(command, reason=reason),
            record=self._record,
            log_event=self.log_event,
        )

    # ---- wiring ---------------------------------------------------------------------------
    def attach_vehicles(self, port: VehiclePort) -> None:
        self._vehicles = port
        self.vehicle_ops.attach(port)

    def attach_measurement_sink(
        self,
        sink: Callable[[Measurement], None],
        lane_sink: Callable[[list[float], Sequence[LaneSource]], None] | None = None,
    ) -> None:
        """``sink`` gets every measurement. Telemetry positions arriving in columns
        (:meth:`on_position_lane`) go to ``lane_sink`` as they came (a list of
        :class:`PositionLane` entries, not to be changed), or without one to ``sink`` as
        Measurements."""
        if lane_sink is not None:
            self._lane_sinks.append(lane_sink)
            self._measurement_sinks.append(sink)
        else:
            self._measurement_sinks.append(sink)
            self._plain_sinks.append(sink)

    def attach_threat_sink(
        self, sink: Callable[[list[Threat]], Awaitable[None]], *, first: bool = False
    ) -> None:
        """Emergency Management's input. ``first``: ahead of the sinks attached before (a
        restart's review must see a new threat before EM does)."""
        if first:
            self._threat_sinks.insert(0, sink)
        else:
            self._threat_sinks.append(sink)

    def attach_answer_sink(self, sink: Callable[[Recommendation, bool], Awaitable[None]]) -> None:
        """Emergency Management hears every accept/reject (it re-plans on reject)."""
        self._answer_sinks.append(sink)

    def attach_operator(self, port: OperatorPort) -> None:
        self._operators.append(port)

    def attach_geofence_listener(
        self, listener: Callable[[Sequence[Geofence]], Awaitable[None]]
    ) -> None:
        self._geofence_listeners.append(listener)

    def _log_threat(self, t: Threat) -> None:
        """Keep an opening or closing for the run report (and what tests look at): without
        the prediction the threat was computed on (every track's trajectory, tens of kB),
        which would make a full log hold hundreds of MB."""
        if len(self.threat_log) == self.threat_log.maxlen:
            self.counters["threat_log_dropped"] += 1
        self.threat_log.append(replace(t, snapshot=None))

    def log_event(self, kind: str, text: str) -> None:
        t_s = self.clock.now_s()
        self.events.append(UsmEvent(t_s=t_s, kind=kind, text=text))
        _log.info("%s: %s", kind, text)

    # ---- telemetry side (adapters.mavlink TelemetrySink, ADS-B, tlog, MQTT) ---------------
    def on_measurement(self, m: Measurement) -> None:
        counters = self.counters
        counters["measurements"] += 1
        sys_id = m.sys_id
        src = (m.source, sys_id, m.icao24, m.operation_id, m.vehicle)
        seen = self._sources.get(src)
        if seen is None:
            if m.source is MeasurementSource.ADSB:
                self._trim_adsb_sources()
            key = f"{m.source.value}:" + (
                str(sys_id) if sys_id is not None else (m.icao24 or m.operation_id or "?")
            )
            if m.vehicle:
                key += f"@{m.vehicle}"
            stats = self._telemetry.setdefault(key, TelemetryStats())
            seen = self._sources[src] = SourceStats(stats)
        seen.stats.add(m)
        # Tracking associates a system id with its operation itself (the same operations, set
        # on every plan change); here it is only counted when no operation claims it.
        if m.operation_id is None and sys_id is not None:
            airspace = self.airspace
            if seen.airspace_version != airspace.version:
                seen.airspace_version = airspace.version
                seen.unknown = airspace.by_sys_id(sys_id) is None
            if seen.unknown:
                counters["unknown_vehicle_measurements"] += 1
        for sink in self._measurement_sinks:
            sink(m)

    def _trim_adsb_sources(self) -> None:
        """Room for one more ADS-B source: over ``max_adsb_sources``, the least recently
        heard eighth is folded into ``adsb:evicted`` (totals kept, detail forgotten)."""
        adsb = {
            k: st.stats.last_capture_t_s
            for k, st in self._sources.items()
            if k[0] is MeasurementSource.ADSB
        }
        old = over_cap_keys(adsb, self.config.max_adsb_sources)
        if not old:
            return
        gone = {id(self._sources[k].stats) for k in old}
        folded = self._telemetry.get("adsb:evicted", TelemetryStats())
        for name, stats in list(self._telemetry.items()):
            if id(stats) in gone:
                del self._telemetry[name]
                folded = folded.combined(stats)
        # (a statistics entry shared by two sources goes with both)
        for k in [k for k, st in self._sources.items() if id(st.stats) in gone]:
            del self._sources[k]
        self._telemetry["adsb:evicted"] = folded
        self.counters["adsb_sources_evicted"] += len(old)

    def _trim_hazard_keys(self, t_s: float) -> None:
        """Forget coalescing keys past their cooldown (they coalesce nothing any more; swept
        as hazards come) and, over ``max_hazard_keys``, the oldest eighth."""
        seen = self._hazard_seen
        cooldown_s = self.config.hazard_cooldown_s
        if len(seen) < self.config.max_hazard_keys and t_s < self._hazard_sweep_t_s:
            return
        self._hazard_sweep_t_s = t_s + cooldown_s / 8.0  # a sweep per eighth of the cooldown
        old = idle_keys(seen, t_s, cooldown_s)
        if len(seen) - len(old) >= self.config.max_hazard_keys:
            old = over_cap_keys(seen, self.config.max_hazard_keys)
        for k in old:
            del seen[k]
            self._hazard_threats.pop(k, None)
        self.counters["hazard_keys_evicted"] += len(old)

    def forget_operations(self, op_ids: Collection[OperationId]) -> None:
        """Operations the airspace forgot (services/retention.py): their recommendations and
        the statistics of sources named by them leave memory (the store keeps the record)."""
        # sources named by the operation alone (kind, sys id, ICAO, operation, vehicle)
        named = [k for k in self._sources if k[3] in op_ids and k[1] is None and k[2] is None]
        gone = {id(self._sources.pop(k).stats) for k in named}
        for key in [k for k, stats in self._telemetry.items() if id(stats) in gone]:
            del self._telemetry[key]
        for rid in [r for r, x in self.recommendations.items() if x.rec.operation_id in op_ids]:
            del self.recommendations[rid]

    @property
    def telemetry(self) -> dict[str, TelemetryStats]:
        """Per source (``telemetry:sys_id[@vehicle]``, ``adsb:icao``, ...): counts and delays
        (a new dict on each read; a key with reports both as Measurements and as lane
        entries has the two combined)."""
        out = dict(self._telemetry)
        lane = self._lane_stats
        lane.fold()
        for key, stats in lane.items():
            mine = out.get(key)
            out[key] = stats if mine is None else mine.combined(stats)
        return out

    def on_position_lane(self) -> None:
        """Take the telemetry positions appended to :attr:`position_lane` since the last call:
        the same accounting as :meth:`on_measurement` gives each of them (counters, per-source
        statistics), then to the lane sinks (tracking) or,
        for sinks without one, as Measurements."""
        lane = self.position_lane
        if lane is None:
            return
        values = lane.take()
        n = len(values) // LANE_STRIDE
        if not n:
            return
        counters = self.counters
        counters["measurements"] += n
        stats = self._lane_stats
        if len(lane.sources) != stats.size:
            self._new_lane_sources(lane)
        if self._lane_version != self.airspace.version:
            self._lane_version = self.airspace.version
            by_sys_id = self.airspace.by_sys_id
            self._lane_unknown = [by_sys_id(src.sys_id) is None for src in lane.sources]
            self._lane_any_unknown = any(self._lane_unknown)
        if self._lane_any_unknown:
            flags = self._lane_unknown
            counters["unknown_vehicle_measurements"] += sum(
                [flags[int(i)] for i in values[0::LANE_STRIDE]]
            )
        stats.add(values)
        for lane_sink in self._lane_sinks:
            lane_sink(values, lane.sources)
        if self._plain_sinks:
            for at in range(0, n * LANE_STRIDE, LANE_STRIDE):
                m = lane.measurement(values, at)
                for sink in self._plain_sinks:
                    sink(m)

    def _new_lane_sources(self, lane: PositionLane) -> None:
        """Statistics for the lane sources registered since the last burst."""
        stats = self._lane_stats
        for src in lane.sources[stats.size :]:
            stats.append(f"telemetry:{src.sys_id}" + (f"@{src.vehicle}" if src.vehicle else ""))
        self._lane_version = -1  # flags for the new sources too

    def on_status(self, s: VehicleStatus) -> None:
        self.statuses[(s.sys_id, s.vehicle)] = s
        flight = self.flight.setdefault((s.sys_id, s.vehicle), FlightState())
        changes = flight.update(s)
        self._flight_by_sys_id[s.sys_id] = flight  # (the latest status of that system id)
        for change in changes:
            if change != "home" and self._transitions.log(
                logging.INFO, f"{s.sys_id}:{change}", "vehicle: sysid %s: %s", s.sys_id, change
            ):
                text = f"sysid {s.sys_id}: {change}"
                self.events.append(UsmEvent(t_s=self.clock.now_s(), kind="vehicle", text=text))
        self.vehicle_ops.on_status(s, flight, changes)  # mission changes, home, progress
        self.airspace.set_airborne(s.sys_id, flight.flying)
        op = self.airspace.by_sys_id(s.sys_id)
        if op is None:
            return
        state = op.state
        if flight.airborne or (
            s.armed and s.mode in (FlightMode.MISSION, FlightMode.TAKEOFF, FlightMode.GUIDED)
        ):
            state = OperationState.ACTIVE
        elif s.armed and s.mode is FlightMode.HOLD and op.state is OperationState.ACTIVE:
            # a hold the UTM did not ask for is still an active flight
            state = OperationState.ACTIVE
        elif flight.phase is Phase.LANDED and op.state is OperationState.ACTIVE:
            state = OperationState.LANDED  # the operation ends when the vehicle lands/disarms
        if state is not op.state and op.state is not OperationState.SUSPENDED:
            self.airspace.set_state(op.id, state)

    def on_ground(self, sys_id: SysId) -> bool:
        """True when the vehicle flying ``sys_id`` (its latest status) says it is on the
        ground (:mod:`gcs_utm.services.flight_state`)."""
        flight = self._flight_by_sys_id.get(sys_id)
        return flight is not None and flight.on_ground

    def on_link_health(self, h: LinkHealth) -> None:
        self.health[(h.sys_id, h.vehicle)] = h

    def statuses_by_sys_id(self) -> dict[SysId, VehicleStatus]:
        """One status per system id: of the vehicles flying it, the latest report."""
        return latest_per_sys_id(self.statuses, lambda s: s.t_s)

    def health_by_sys_id(self) -> dict[SysId, LinkHealth]:
        """One link health per system id: of the vehicles flying it, the most recently heard
        (the one an operation naming that system id is flying now)."""
        return latest_per_sys_id(self.health, lambda h: h.last_heard_t_s)

    def on_vehicle(self, v: object) -> None:
        """A newly heard vehicle: its mission becomes an operation (see
        :mod:`gcs_utm.services.vehicle_ops`; paper: operations come from the pilots' ground
        stations)."""
        key = getattr(v, "key", None)
        self.log_event("vehicle", f"vehicle discovered: sysid {getattr(key, 'sys_id', None)}")
        self.vehicle_ops.on_vehicle(v)

    def on_hazard(self, h: HazardReport) -> None:
        """A hazard from outside Monitoring becomes a threat for EM, coalesced per
        (kind, UAS) within the cooldown so a flapping GNSS does not storm the operator."""
        self.counters["hazards"] += 1
        if h.kind in _VEHICLE_HAZARDS and (
            (h.sys_id is not None and self.on_ground(h.sys_id))
            or (h.operation_id is not None and self.airspace.airborne(h.operation_id) is False)
        ):
            # a vehicle on the ground (acquiring GNSS, rebooted, link gone) is in pre-flight:
            # its checks are the pilot's, not an emergency of the airspace
            self.counters["hazards_on_ground"] += 1
            who = h.operation_id or f"sysid {h.sys_id}"
            self.log_event("preflight", f"{who} on the ground: {h.kind.value} {h.message}")
            return
        op_id = h.operation_id
        if op_id is None and h.sys_id is not None:
            op = self.airspace.by_sys_id(h.sys_id)
            op_id = op.id if op is not None else None
        key = (h.kind, op_id or (h.source or "airspace") + ":" + (h.area.id if h.area else ""))
        if key not in self._hazard_seen:
            self._trim_hazard_keys(h.t_s)
        last = self._hazard_seen.get(key)
        if last is not None and h.t_s - last < self.config.hazard_cooldown_s:
            self.counters["hazards_coalesced"] += 1
            if (open_id := self._hazard_threats.get(key)) is not None:
                self.threat_closer.repeated(open_id, h.t_s)
            return
        self._hazard_seen[key] = h.t_s
        threat = Threat(
            id=ThreatId(f"{self.id_prefix}{h.kind.value.lower()}-{next(self._hazard_seq)}"),
            kind=h.kind,
            uas_ids=(op_id,) if op_id is not None else (),
            detected_at_s=h.t_s,
            predicted_event_at_s=h.t_s,
            position=h.position,
            area=h.area,
            message=h.message,
        )
        self._hazard_threats[key] = threat.id
        self.threat_closer.watch(threat, h.sys_id)
        self._spawn(self.on_threats([threat]))

    def operation_or_none(self, op_id: OperationId) -> Operation | None:
        """The airspace's operation ``op_id``, None when there is none."""
        try:
            return self.airspace.operation(op_id)
        except AirspaceError:
            return None

    def attach_threat_evidence(
        self,
        last_position_t_s: Callable[[OperationId], float | None],
        *,
        fresh_s: float,
        eph_good_m: float,
    ) -> None:
        """What tells the threat closer that positions flow again (tracking: a position
        newer than ``fresh_s`` ends a link loss) and that a GNSS fix is good again."""
        closer = self.threat_closer
        closer.evidence = replace(closer.evidence, last_position_t_s=last_position_t_s)
        closer.fresh_s, closer.eph_good_m = fresh_s, eph_good_m

    async def _close_threat(self, closed: Threat, reason: str) -> None:
        """A hazard's threat is over (see :mod:`.threat_lifecycle`): closed in the store, on
        the operator's views and for EM (which drops its geofences), with the reason audited;
        the same hazard raised later is a new threat (not coalesced into this one)."""
        for key in [k for k, v in self._hazard_threats.items() if v == closed.id]:
            del self._hazard_threats[key]
            self._hazard_seen.pop(key, None)
        self._record(
            AuditEntry(
                t_s=self.clock.now_s(),
                actor="usm",
                action="threat_closed",
                subject=closed.id,
                detail={"kind": closed.kind.value, "reason": reason},
            )
        )
        text = f"{closed.message}; closed: {reason}" if closed.message else f"closed: {reason}"
        await self.on_threats([replace(closed, message=text)])

    async def run(self, period_s: float = 0.5) -> None:
        """Housekeeping every ``period_s`` clock seconds: recommendation deadlines, and the
        threats of hazards whose cause is gone."""
        while True:
            await self.lifecycle.expire_due()
            await self.threat_closer.check(self.clock.now_s())
            await self.clock.sleep(period_s)

    async def on_threats(self, threats: list[Threat]) -> None:
        """From Monitoring (and hazards): record, then hand to EM."""
        if not threats:
            return
        for t in threats:
            first = t.id not in self.threats
            if t.status is ThreatStatus.CLOSED:
                self.threats.pop(t.id, None)
            else:
                self.threats[t.id] = t
            if first or t.status is ThreatStatus.CLOSED:
                self._log_threat(t)
                self._record(t)
                uas = ",".join(t.uas_ids) or "-"
                self.log_event(
                    "threat",
                    f"{t.kind.value} {uas} {t.status.value}"
                    + (f" {t.message}" if t.message else ""),
                )
        for sink in self._threat_sinks:
            await sink(threats)

    async def add_geofences(self, geofences: Sequence[Geofence]) -> None:
        changed = [g for g in geofences if self.airspace.add_geofence(g)]
        for g in changed:
            self.log_event("geofence", f"geofence {g.id} created ({g.reason or g.kind.value})")
        if changed:
            for listener in self._geofence_listeners:
                await listener(self.airspace.geofences())

    async def remove_geofences(self, geofence_ids: Sequence[GeofenceId]) -> None:
        """EM's geofences whose threat closed leave the airspace (and the store's active
        ones)."""
        removed = [g for g in geofence_ids if self.airspace.remove_geofence(g)]
        for g in removed:
            self.log_event("geofence", f"geofence {g} removed (its threat closed)")
        if removed:
            for listener in self._geofence_listeners:
                await listener(self.airspace.geofences())

    async def escalate(self, text: str) -> None:
        self.log_event("escalation", text)
        self._record(
            AuditEntry(
                t_s=self.clock.now_s(),
                actor="em",
                action="escalate",
                subject=text[:80],
                detail={"text": text},
            )
        )

    # ---- recommendations (the lifecycle part: gcs_utm.services.recommendations) -----------
    async def on_recommendation(self, rec: Recommendation) -> None:
        """A proposal (or a new version, or EM's end of one) from EM to the operators."""
        await self.lifecycle.on_recommendation(rec)

    async def on_superseded(self, rec_id: RecommendationId) -> None:
        await self.lifecycle.on_superseded(rec_id)

    async def on_expired(self, rec_id: RecommendationId) -> None:
        await self.lifecycle.on_expired(rec_id)

    async def answer(self, a: PilotAnswer) -> AnswerOutcome:
        """An operator's answer, matched to the exact id and version it names."""
        return await self.lifecycle.answer(a)

    async def expire_due(self) -> None:
        await self.lifecycle.expire_due()

    def pending(self) -> list[Recommendation]:
        """The recommendations waiting for an answer."""
        return self.lifecycle.pending()

    async def execute_command(self, command: Command, *, reason: str = "") -> bool:
        """Send a command (autonomous mode or an accepted recommendation)."""
        op = self.airspace.operation(command.operation_id)
        if self._vehicles is None or op.sys_id is None:
            self.log_event("command", f"{command.kind.value} for {op.id}: no vehicle link")
            return False
        result = await self._vehicles.send_command(op.sys_id, command)
        self._record(
            AuditEntry(
                t_s=self.clock.now_s(),
                actor="usm",
                action=f"command_{command.kind.value}",
                subject=op.id,
                detail={"ok": result.ok, "error": result.error, "reason": reason},
            )
        )
        self.log_event(
            "command",
            f"{command.kind.value} for {op.id}: "
            + ("acknowledged" if result.ok else f"failed ({result.error})"),
        )
        if result.ok and command.kind in (CommandKind.HOLD, CommandKind.LAND):
            self.airspace.set_state(op.id, OperationState.SUSPENDED)
        if result.ok and command.kind is CommandKind.RESUME:
            self.airspace.set_state(op.id, OperationState.ACTIVE)
        return result.ok

    async def operator_command(
        self, uas: str, command: str, *, operator: str, source: str, request_id: str = ""
    ) -> CommandResult:
        """An operator's hold / land / rtl / resume for ``uas`` from any channel: checked,
        sent as EM's commands are, verified and audited (:mod:`.operator_commands`)."""
        return await self.operator_commands.command(
            uas, command, operator=operator, source=source, request_id=request_id
        )

    def _spawn(self, coro: Awaitable[None]) -> None:
        task = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[None]) -> None:
        """A failed task is logged once per interval and cause (its coroutine and error
        type), the first with its traceback, the repeats counted: a sender that makes the
        same task fail on every frame cannot flood the log."""
        self._tasks.discard(task)
        if task.cancelled() or (exc := task.exception()) is None:
            return
        coro = task.get_coro()
        where = getattr(coro, "__qualname__", type(coro).__name__)
        self._task_errors.log(
            logging.ERROR,
            f"{where}:{type(exc).__name__}",
            "USM task %s failed: %s: %s",
            where,
            type(exc).__name__,
            exc,
            exc_info=exc,
        )

    async def drain(self) -> None:
        """Wait for spawned work (uploads, hazard forwarding) to finish."""
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)

    async def close(self) -> None:
        for t in list(self._tasks):
            t.cancel()
        await asyncio.gather(*list(self._tasks), return_exceptions=True)
