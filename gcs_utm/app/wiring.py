"""The one builder of the running service, used by ``serve`` and by scenario runs alike.

    MAVLink hub --(TelemetrySink)--> USM --> TrackingService --> snapshot
    MonitoringService (periodic, on Airspace.snapshot) --threats--> USM --> EmergencyService
    EmergencyService --Decision--> USM: geofences into the airspace, recommendations to the
    operator (dashboard / headless+auto / MQTT), commands; answers --> USM --> upload --> plan

:func:`build_runtime` builds and connects the parts (no task started, no socket opened);
:func:`attach_frontends` connects whoever answers recommendations (dashboard with the
configured operator name, headless view, automatic operator, MQTT gateway);
:func:`start_service_tasks` starts the named tasks of one ``asyncio.TaskGroup``.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from adapters.mavlink import MavlinkHub
from adapters.mavlink.traffic_out import TrafficOut
from adapters.remoteid.ingest import (
    RidAircraft,
    RidIngest,
    identity_audit,
    telemetry_positions,
)
from adapters.remoteid.operator import RemoteIdOperator
from adapters.remoteid.tracks import RidTracks
from gcs_utm.clock import Clock
from gcs_utm.cluster.selffence import FencedVehicles, OwnedTraffic
from gcs_utm.core.deconfliction import TacticalDeconfliction
from gcs_utm.core.deconfliction.retime import retime_snapshot
from gcs_utm.core.emergency import Decision, EmergencyManager
from gcs_utm.core.monitoring import Monitor
from gcs_utm.core.tracking import Tracker
from gcs_utm.dashboard.headless import HeadlessView
from gcs_utm.dashboard.line import LinePrompt
from gcs_utm.dashboard.view import Minima
from gcs_utm.geo import LocalFrame
from gcs_utm.messages import HazardReport, PilotAnswer, PilotDecision
from gcs_utm.model import (
    AuditEntry,
    FlightPlan,
    Geofence,
    Operation,
    OperationId,
    Recommendation,
    RemoteIdentity,
    Threat,
    Track,
    TrackId,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.emergency import EmergencyService
from gcs_utm.services.monitoring import MonitoringService
from gcs_utm.services.operator import AutoOperator
from gcs_utm.services.recorder import LinkRecorder
from gcs_utm.services.retention import Retention
from gcs_utm.services.strategic import FilingCheck
from gcs_utm.services.surveillance import SurveillanceService
from gcs_utm.services.tracking import TrackingService
from gcs_utm.services.usm import Usm
from gcs_utm.settings import Settings
from gcs_utm.store import StoreWriter
from gcs_utm.store.ids import life_prefix

from .stopping import Stopping, closing_steps, run_steps

if TYPE_CHECKING:
    from gcs_utm.cluster.policy import OwnershipPolicy
    from gcs_utm.dashboard.tui import DashboardApp
    from gcs_utm.services.mqtt_gateway import MqttGateway

_log = logging.getLogger(__name__)

TrackSample = tuple[float, float, float, float, float, float]
"""(t_s, lat_deg, lon_deg, alt_amsl_m, east_m, north_m) of one track at one sampling."""


class OperatorMode:
    DASHBOARD = "dashboard"
    AUTO_ACCEPT = "auto-accept"
    AUTO_REJECT = "auto-reject"
    LINE = "line"  # headless, answers typed on stdin (gcs_utm.dashboard.line)
    NONE = "none"  # answers only from MQTT


class Persistence:
    """The store as the services see it: every write goes to the one writer thread (nothing
    blocks the event loop); track batches may be dropped when the queue is full (counted),
    decisions and audit never are."""

    def __init__(self, writer: StoreWriter) -> None:
        self.writer = writer

    def record(self, obj: object) -> None:
        if isinstance(obj, Threat):
            self.writer.save_threat(obj)
        elif isinstance(obj, Recommendation):
            self.writer.save_recommendation(obj)
        elif isinstance(obj, AuditEntry):
            self.writer.audit(obj)
        elif isinstance(obj, PilotAnswer):
            self.writer.record_answer(obj)
        else:
            _log.error("nothing stores a %s", type(obj).__name__)

    def save_plan(self, plan: FlightPlan) -> None:
        self.writer.save_plan(plan)

    def save_operation(self, op: Operation) -> None:
        self.writer.save_operation(op)

    def save_geofence(self, g: Geofence) -> None:
        self.writer.save_geofence(g)

    def deactivate_geofence(self, geofence_id: str) -> None:
        self.writer.deactivate_geofence(geofence_id)

    def write_tracks(self, tracks: list[Track]) -> None:
        self.writer.write_tracks(tracks)

    def write_remote_ids(self, rows: list[tuple[TrackId, RemoteIdentity]]) -> None:
        self.writer.write_remote_ids(rows)

    @property
    def epoch(self) -> int:
        """The store life this process writes in (ids carry it, see gcs_utm.store.ids)."""
        return self.writer.epoch

    def close(self) -> None:
        self.writer.close()


@dataclass
class Runtime:
    """Every built part, so the CLI, the report and tests can look inside; and the owner of
    their lifetime, the same for ``serve``, ``run``, ``demo`` and ``eval``: the start (links
    opened, frontends attached, a cluster joined) runs inside ``async with rt:``, so a failure
    anywhere in it still tears down what was started, and leaving the block (or
    :meth:`close`) tears down once, in the order of
    :func:`gcs_utm.app.stopping.closing_steps`."""

    settings: Settings
    clock: Clock
    frame: LocalFrame
    store: Persistence
    airspace: Airspace
    usm: Usm
    tracker: Tracker
    tracking: TrackingService
    monitoring: MonitoringService
    emergency: EmergencyService
    hub: MavlinkHub
    surveillance: SurveillanceService  # [adsb] receiver feeds (none unless enabled)
    remote_id: RemoteIdOperator  # the operator's Remote ID part to vehicles (docs/remote-id.md)
    remote_id_ingest: RidIngest  # what vehicles report of Remote ID
    remote_id_tracks: RidTracks  # ... put on the tracks the views, MQTT and the store get
    traffic_out: TrafficOut  # ADSB_VEHICLE to vehicles for the traffic near them
    plan_history: dict[OperationId, list[FlightPlan]] = field(default_factory=dict)
    geofence_history: dict[str, Geofence] = field(default_factory=dict)
    samples: dict[TrackId, list[TrackSample]] = field(default_factory=dict)
    retention: Retention | None = None  # forgets what ended long ago (services/retention.py)
    filing: FilingCheck | None = None  # the strategic check of filed plans (services/strategic.py)
    recorder: LinkRecorder | None = None  # --record: closed after the links
    # a blocking close step (the store's) runs on a thread, bounded; inline on a fast-time
    # loop, which does not wait for threads (gcs_utm.app.stopping.run_steps)
    close_in_threads: bool = True
    _closed: bool = field(default=False, init=False, repr=False)

    def tracks(self) -> dict[TrackId, Track]:
        return self.remote_id_tracks.attach(self.tracking.tracks_now())

    async def __aenter__(self) -> Runtime:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self, stopping: Stopping | None = None) -> None:
        """Tear down once (a second call does nothing): drain the USM (unless ``stopping``
        is a fenced member's), close it, the links, the recorder and the store, each step
        within ``stopping``'s budget (default: a plain stop's, from now)."""
        if self._closed:
            return
        self._closed = True
        stopping = stopping or Stopping(fenced=False)
        steps = closing_steps(self, self.store, self.recorder, stopping)
        await run_steps(stopping, steps, threads=self.close_in_threads)


def build_runtime(
    settings: Settings,
    clock: Clock,
    frame: LocalFrame,
    store: Persistence,
    *,
    policy: OwnershipPolicy | None = None,
) -> Runtime:
    """Build and connect the parts (no task started, no socket opened, nothing process-wide
    changed: see :func:`gcs_utm.app.configure_interpreter` for that). ``policy``: a cluster
    member's ownership rule (``serve --cluster``): only the threats it decides reach its USM
    and EM, and its recommendations for other instances' operations go to the store only."""
    plan_history: dict[OperationId, list[FlightPlan]] = {}
    geofence_history: dict[str, Geofence] = {}
    tracker = Tracker(frame, settings.tracking)
    tracking_ref: list[TrackingService] = []

    def on_plan(plan: FlightPlan) -> None:
        plan_history.setdefault(plan.operation_id, []).append(plan)
        store.save_plan(plan)
        for tracking_service in tracking_ref:
            tracking_service.set_operations(airspace.operations.values())

    def on_geofence(g: Geofence, active: bool) -> None:
        geofence_history[g.id] = g
        if active:
            store.save_geofence(g)
        else:
            store.deactivate_geofence(g.id)

    def on_operation(op: Operation) -> None:
        store.save_operation(op)
        filing.on_operation(op)  # the strategic check of a newly filed plan

    airspace = Airspace(on_operation=on_operation, on_plan=on_plan, on_geofence=on_geofence)
    id_prefix = life_prefix(store.epoch)
    usm = Usm(
        airspace,
        clock,
        config=settings.usm,
        record=store.record,
        id_prefix=id_prefix,
        ground_elevation_amsl_m=frame.ground_elevation_amsl_m,
    )

    filing = FilingCheck(
        frame,
        settings.monitoring,
        operations=lambda: airspace.operations,
        log_event=usm.log_event,
        airborne=airspace.airborne_ids,
        geofences=airspace.geofences,
    )

    on_hazard = usm.on_hazard if policy is None else _admitted(usm.on_hazard, policy)
    tracking_hazard = _in_loop(on_hazard)

    # Remote ID records (rid_ingest, below) on the tracks: docs/remote-id.md
    rid_tracks = RidTracks(
        lambda: rid_ingest.aircraft,
        lambda: airspace.operations.values(),  # noqa: PLW0108 - a property
    )
    tracking = TrackingService(
        tracker,
        clock,
        on_hazard=tracking_hazard,
        track_sink=rid_tracks.track_sink(store.write_tracks, store.write_remote_ids),
        ingest_delay_s=settings.tracking.ingest_delay_s,
    )
    tracking_ref.append(tracking)

    def snapshot(t_s: float) -> Any:
        return airspace.snapshot(t_s, tracking.snapshot)

    monitor = Monitor(frame, settings.monitoring, id_prefix=id_prefix)
    monitoring = MonitoringService(
        monitor,
        snapshot,
        clock,
        usm.on_threats if policy is None else _filtered(usm.on_threats, policy),
        period_s=settings.monitoring.period_s,
    )
    td = TacticalDeconfliction(frame, settings.deconfliction, settings.monitoring)
    em = EmergencyManager(frame, settings.emergency, td, settings.monitoring)

    async def on_decision(decision: Decision) -> None:
        await apply_decision(
            usm,
            decision,
            store,
            owns=None if policy is None else policy.owns,
            file=None if policy is None else policy.filer,
            policy=policy,
        )

    def em_snapshot(t_s: float) -> Any:
        # EM/TD decide on the plans as they are being flown (re-timed by each UAS's delay),
        # the same timing Monitoring predicted the threat with
        return retime_snapshot(snapshot(t_s), frame)

    emergency = EmergencyService(em, em_snapshot, clock, on_decision)
    usm.attach_measurement_sink(tracking.submit, tracking.submit_lane)
    usm.attach_threat_evidence(
        lambda op_id: tracker.last_accepted_t_s(TrackId(op_id)),
        fresh_s=settings.tracking.stale_after_s,
        eph_good_m=settings.mavlink.eph_degraded_m / 2.0,  # where the vehicle re-arms it
    )
    usm.attach_threat_sink(
        emergency.submit_threats if policy is None else _filtered(emergency.submit_threats, policy)
    )

    async def answer_sink(rec: Recommendation, accepted: bool) -> None:
        await emergency.submit_answer(rec.id, rec.version, accepted)

    usm.attach_answer_sink(answer_sink)
    # EM hears how each accepted recommendation ended (applied, or failed: re-plan, then the
    # safe command), so a failed upload never leaves its threat without a pending decision.
    _attach_emergency(usm, emergency)
    hub = MavlinkHub(settings.mavlink, clock, usm)
    usm.attach_vehicles(hub if policy is None else FencedVehicles(hub, policy.may_act))

    rid_ingest = _remote_id_ingest(settings, hub, usm, store)
    # What gcs-utm sends to the vehicles unasked (traffic, the operator's Remote ID part): in a
    # cluster only to the vehicles this instance owns, within its lease (behind a router every
    # instance hears every vehicle).
    to_vehicles = hub if policy is None else OwnedTraffic(hub, policy, airspace.by_sys_id)

    return Runtime(
        settings=settings,
        clock=clock,
        frame=frame,
        store=store,
        airspace=airspace,
        usm=usm,
        tracker=tracker,
        tracking=tracking,
        monitoring=monitoring,
        emergency=emergency,
        hub=hub,
        surveillance=SurveillanceService(settings.adsb, clock, usm.on_measurement),
        remote_id=RemoteIdOperator(
            settings.remote_id,
            clock,
            to_vehicles,
            vehicles=hub.remote_id,
            known=hub.vehicles,
            operations=lambda: airspace.operations.values(),  # noqa: PLW0108 - a property
            on_problem=lambda text: usm.log_event("remote_id", text),
            on_hazard=on_hazard,
        ),
        remote_id_ingest=rid_ingest,
        remote_id_tracks=rid_tracks,
        traffic_out=TrafficOut(
            settings.traffic_out,
            to_vehicles,
            tracks=tracking.tracks_now,
            operations=lambda: airspace.operations.values(),  # noqa: PLW0108 - a property
        ),
        plan_history=plan_history,
        geofence_history=geofence_history,
        retention=_retention(
            clock,
            airspace,
            tracking,
            (usm, em, filing),
            plans=plan_history,
            fences=geofence_history,
        ),
        filing=filing,
    )


def _remote_id_ingest(
    settings: Settings, hub: MavlinkHub, usm: Usm, store: Persistence
) -> RidIngest:
    """The vehicles' OPEN_DRONE_ID_* reports (docs/remote-id.md), each identity logged and
    audited."""

    def rid_identity(rec: RidAircraft, text: str) -> None:
        usm.log_event("remote_id", text)
        store.record(identity_audit(rec))

    rid_ingest = RidIngest(
        consistency_m=settings.remote_id.consistency_m,
        position_of=telemetry_positions(hub),
        on_identity=rid_identity,
    )
    rid_ingest.register(hub.remote_id)
    return rid_ingest


def _attach_emergency(usm: Usm, emergency: EmergencyService) -> None:
    """EM hears how each accepted recommendation ends, and checks each accepted plan again
    against the airspace as it is right before its upload (gcs_utm.core.emergency.recheck)."""
    usm.attach_operator(emergency)
    usm.lifecycle.plan_check = emergency.plan_problem


def _in_loop(fn: Callable[[HazardReport], None]) -> Callable[[HazardReport], Awaitable[None]]:
    async def called(h: HazardReport) -> None:
        fn(h)

    return called


def _admitted(
    on_hazard: Callable[[HazardReport], None], policy: OwnershipPolicy
) -> Callable[[HazardReport], None]:
    """A cluster member's hazards: see :meth:`OwnershipPolicy.admits_hazard`."""

    def admitted(h: HazardReport) -> None:
        if policy.admits_hazard(h):
            on_hazard(h)

    return admitted


def _retention(
    clock: Clock,
    airspace: Airspace,
    tracking: TrackingService,
    keepers: tuple[Usm, EmergencyManager, FilingCheck],
    *,
    plans: dict[OperationId, list[FlightPlan]],
    fences: dict[str, Geofence],
) -> Retention:
    """What ended an hour ago leaves memory (services/retention.py): the operations' tracks,
    their USM and EM recommendations, what their filing found, their histories, and the
    geofences that ended as long ago."""

    def forgotten(op_ids: list[OperationId]) -> None:
        tracking.set_operations(airspace.operations.values())  # drops their tracks
        for keeper in keepers:
            keeper.forget_operations(set(op_ids))
        for op_id in op_ids:
            plans.pop(op_id, None)
        old_s = clock.now_s() - retention.keep_s
        for g in [g for g in fences.values() if (g.end_t_s or math.inf) < old_s]:
            del fences[g.id]

    retention = Retention(airspace=airspace, on_forgotten=forgotten)
    return retention


def _filtered(
    sink: Callable[[list[Threat]], Awaitable[None]], policy: OwnershipPolicy
) -> Callable[[list[Threat]], Awaitable[None]]:
    async def filtered(threats: list[Threat]) -> None:
        kept = policy.filter_threats(threats)
        if kept:
            await sink(kept)

    return filtered


async def apply_decision(
    usm: Usm,
    decision: Decision,
    store: Persistence,
    *,
    owns: Callable[[OperationId], bool] | None = None,
    file: Callable[[Recommendation], Awaitable[None]] | None = None,
    policy: OwnershipPolicy | None = None,
) -> None:
    """Carry an EM decision to the world through the USM. Order matters: geofences first so
    the operator sees why, then superseded proposals, then new recommendations. ``owns``
    (cluster): a recommendation for an operation of another instance is filed in the store
    for its owner (gcs_utm.cluster.policy), not proposed here: by ``file`` (the cluster
    node's version allocation) when given; a command for such an operation travels with its
    filed recommendation and its owner sends it (gcs_utm.cluster.decisions). ``policy``: a
    cluster member whose lease deadline passed (``policy.may_act``) carries out nothing."""
    if policy is not None and not policy.may_act():
        policy.dropped_stale += 1
        return
    for entry in decision.audit:
        store.record(entry)
    if decision.geofences:
        await usm.add_geofences(decision.geofences)
    if decision.removed_geofences:
        await usm.remove_geofences(decision.removed_geofences)
    for rec_id in decision.superseded:
        await usm.on_superseded(rec_id)
    for rec in decision.recommendations:
        if owns is not None and not owns(rec.operation_id):
            if file is not None:
                await file(rec)
                continue
            store.record(rec)
            usm.log_event(
                "cluster", f"{rec.id} v{rec.version}: filed for {rec.operation_id}'s owner"
            )
            continue
        await usm.on_recommendation(rec)
    for command in decision.commands:
        if owns is not None and not owns(command.operation_id):
            continue  # sent by the operation's owner, from the filed recommendation
        await usm.execute_command(command, reason="autonomous mode")
    for text in decision.escalations:
        await usm.escalate(text)
    for text in decision.warnings:
        usm.log_event("warning", text)


@dataclass(frozen=True, slots=True, kw_only=True)
class FrontendOptions:
    """Who sees and answers recommendations. ``headless``: no TUI; ``quiet``: not even the
    headless log lines (batch evaluation); ``mqtt``: start the MQTT gateway even when the
    settings leave it off."""

    operator: str = OperatorMode.DASHBOARD
    headless: bool = False
    quiet: bool = False
    mqtt: bool = False
    reject_first: int = 0


@dataclass(frozen=True, slots=True, kw_only=True)
class Frontends:
    """What :func:`attach_frontends` attached, for the tasks that run them."""

    headless: HeadlessView | None
    dashboard: DashboardApp | None
    gateway: MqttGateway | None
    line: LinePrompt | None = None


def minima(settings: Settings) -> Minima:
    """The separation minima the operator's views show."""
    mon = settings.monitoring
    return Minima(
        horizontal_m=mon.separation_horizontal_m,
        vertical_m=mon.separation_vertical_m,
        intruder_horizontal_m=mon.intruder_horizontal_m,
        intruder_vertical_m=mon.intruder_vertical_m,
        safety_distance_m=mon.safety_distance_m if mon.spherical else None,
    )


def attach_frontends(rt: Runtime, options: FrontendOptions) -> Frontends:
    """Attach the operator ports to the USM, the same way for ``serve`` and ``run``: the
    dashboard and the line prompt answer under the configured operator name
    (``dashboard.operator``)."""
    settings = rt.settings
    shown = minima(settings)
    dashboard = None
    if options.operator == OperatorMode.DASHBOARD and not options.headless:
        from gcs_utm.dashboard.tui import DashboardApp

        dashboard = DashboardApp(
            rt.usm,
            rt.tracks,
            refresh_s=settings.dashboard.refresh_s,
            operator=settings.dashboard.operator,
            minima=shown,
        )
        rt.usm.attach_operator(dashboard)
    mqtt = options.mqtt or settings.mqtt.enabled
    headless = line = None
    if options.operator == OperatorMode.LINE:
        line = LinePrompt(rt.usm, rt.tracks, operator=settings.dashboard.operator, minima=shown)
        rt.usm.attach_operator(line)
    elif dashboard is None and not options.quiet:
        by = options.operator if options.operator != OperatorMode.NONE else ""
        by = by or ("MQTT (remote pilot station)" if mqtt else "")
        headless = HeadlessView(rt.usm, rt.tracks, answered_by=by, minima=shown)
        rt.usm.attach_operator(headless)
    if options.operator in (OperatorMode.AUTO_ACCEPT, OperatorMode.AUTO_REJECT):
        # New plans start where the UAS will be when the answer comes: after this delay.
        rt.emergency.em.lead.answer_delay_s = settings.dashboard.auto_answer_delay_s
        rt.usm.attach_operator(
            AutoOperator(
                rt.usm.answer,
                rt.clock,
                decision=PilotDecision.ACCEPT
                if options.operator == OperatorMode.AUTO_ACCEPT
                else PilotDecision.REJECT,
                delay_s=settings.dashboard.auto_answer_delay_s,
                reject_first=options.reject_first,
            )
        )
    gateway = None
    if mqtt:
        from gcs_utm.services.mqtt_gateway import MqttGateway

        gateway = MqttGateway(rt.usm, settings.mqtt, tracks=rt.tracks, frame=rt.frame)
        rt.usm.attach_operator(gateway)
        rt.usm.attach_threat_sink(gateway.on_threats)
        rt.usm.attach_geofence_listener(gateway.on_geofences)
    return Frontends(headless=headless, dashboard=dashboard, gateway=gateway, line=line)


def start_service_tasks(
    tg: asyncio.TaskGroup, rt: Runtime, frontends: Frontends
) -> list[asyncio.Task[Any]]:
    """The service's named tasks; the dashboard's task is the last one when there is one."""
    tasks: list[asyncio.Task[Any]] = [
        tg.create_task(rt.tracking.run(), name="tracking"),
        tg.create_task(rt.monitoring.run(), name="monitoring"),
        tg.create_task(rt.emergency.run(), name="emergency"),
        tg.create_task(rt.usm.run(), name="usm"),
        tg.create_task(rt.surveillance.run(), name="adsb"),
        tg.create_task(rt.remote_id.run(), name="remote-id"),
        tg.create_task(rt.traffic_out.run(), name="traffic-out"),
    ]
    if rt.retention is not None:
        tasks.append(tg.create_task(rt.retention.run(rt.clock), name="retention"))
    if frontends.headless is not None:
        tasks.append(tg.create_task(_headless_status(rt, frontends.headless), name="status"))
    if frontends.line is not None:
        tasks.append(tg.create_task(frontends.line.run(), name="line"))
    if frontends.gateway is not None:
        tasks.append(tg.create_task(frontends.gateway.run(), name="mqtt"))
    if frontends.dashboard is not None:
        tasks.append(tg.create_task(frontends.dashboard.run_async(), name="dashboard"))
    return tasks


async def _headless_status(rt: Runtime, view: HeadlessView) -> None:
    while True:
        await asyncio.sleep(rt.settings.dashboard.headless_status_s)
        view.status()
