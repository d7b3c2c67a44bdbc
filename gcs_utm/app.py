"""The composition root: reads settings, builds the concrete parts, connects them, and runs them
as one ``asyncio.TaskGroup`` of named tasks.

    MAVLink hub --(TelemetrySink)--> USM --> TrackingService --> snapshot
    MonitoringService (periodic, on Airspace.snapshot) --threats--> USM --> EmergencyService
    EmergencyService --Decision--> USM: geofences into the airspace, recommendations to the
    operator (dashboard / headless+auto / MQTT), commands; answers --> USM --> upload --> plan

``run_scenario`` additionally starts the scenario's simulated vehicles (``sitl``) on the same
simulated clock, plays the scenario's events, and writes the JSON report and figures.
``serve`` is the long-running service: links from config, persistent store, resume on restart.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import signal
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from adapters.mavlink import MavlinkHub
from gcs_utm.clock import Clock, RealClock, ScaledClock
from gcs_utm.core.deconfliction import TacticalDeconfliction
from gcs_utm.core.deconfliction.retime import retime_snapshot
from gcs_utm.core.emergency import Decision, EmergencyManager
from gcs_utm.core.monitoring import Monitor
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.geometry import points_in_edges
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
    GeofenceShape,
    Operation,
    OperationId,
    Recommendation,
    Threat,
    ThreatKind,
    Track,
    TrackId,
)
from gcs_utm.scenario import Scenario
from gcs_utm.scenario.types import EventKind, ScenarioEvent
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.emergency import EmergencyService
from gcs_utm.services.monitoring import MonitoringService
from gcs_utm.services.operator import AutoOperator
from gcs_utm.services.recorder import record_links
from gcs_utm.services.surveillance import SurveillanceService
from gcs_utm.services.tracking import TrackingService
from gcs_utm.services.usm import Usm
from gcs_utm.settings import Settings
from gcs_utm.store import Store, StoreWriter
from gcs_utm.store.ids import life_prefix

_log = logging.getLogger(__name__)


class OperatorMode:
    DASHBOARD = "dashboard"
    AUTO_ACCEPT = "auto-accept"
    AUTO_REJECT = "auto-reject"
    LINE = "line"  # headless, answers typed on stdin (gcs_utm.dashboard.line)
    NONE = "none"  # answers only from MQTT


@dataclass(frozen=True, slots=True, kw_only=True)
class RunOptions:
    """Options of ``gcs-utm run`` (and ``demo``)."""

    speed: float = 1.0
    headless: bool = False
    operator: str = OperatorMode.DASHBOARD
    reject_first: int = 0
    external: bool = False
    link: str | None = None
    mqtt: bool = False
    out_dir: Path = Path("runs")
    duration_s: float | None = None
    figures: bool = True
    lead_s: float | None = None
    record_dir: Path | None = None  # record every MAVLink link as a .tlog here


# ---- the running system ----------------------------------------------------------------------


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

    @property
    def epoch(self) -> int:
        """The store life this process writes in (ids carry it, see gcs_utm.store.ids)."""
        return self.writer.epoch

    def close(self) -> None:
        self.writer.close()


@dataclass
class Runtime:
    """Every built part, so the CLI, the report and tests can look inside."""

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
    plan_history: dict[OperationId, list[FlightPlan]] = field(default_factory=dict)
    geofence_history: dict[str, Geofence] = field(default_factory=dict)
    samples: dict[TrackId, list[tuple[float, float, float, float, float, float]]] = field(
        default_factory=dict
    )

    def tracks(self) -> dict[TrackId, Track]:
        tracks: dict[TrackId, Track] = self.tracking.snapshot()[0]
        return tracks


GIL_SWITCH_INTERVAL_S = 0.0002
"""The event loop shares the interpreter with the store's writer thread, which holds the GIL
for ~10-15 ms when it encodes a second's tracks (1,000 tracks). With Python's default switch
interval (5 ms) the loop waits up to 5 ms at each switch; this bounds each wait. Measured side
by side at 10,000 msg/s with the store attached: 0.5 ms against the default (4 runs each, a
noisy host), p99 receipt-to-track 5.6-10.9 ms against 9.9-23.5 ms; 0.2 ms against 0.5 ms (14
pairs of 5 s runs, fresh processes, a quiet host, 2026-11-25), p99 median 3.7 against 4.2 ms,
lower in 12 of 14 pairs, under 5 ms in 12 against 10 of 14. CPU per message at 30,000 msg/s
the same within noise (0.2 ms: 19.8-24.7 µs, 0.5 ms: 20.5-22.7 µs, 4 runs each, all
lossless)."""


def configure_interpreter() -> None:
    """Process-wide settings the running service needs (see GIL_SWITCH_INTERVAL_S)."""
    if sys.getswitchinterval() > GIL_SWITCH_INTERVAL_S:
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)


def build_runtime(
    settings: Settings, clock: Clock, frame: LocalFrame, store: Persistence
) -> Runtime:
    """Build and connect the parts (no task started, no socket opened)."""
    configure_interpreter()
    plan_history: dict[OperationId, list[FlightPlan]] = {}
    geofence_history: dict[str, Geofence] = {}
    tracker = Tracker(frame, settings.tracking)
    holder: dict[str, Any] = {}

    def on_plan(plan: FlightPlan) -> None:
        plan_history.setdefault(plan.operation_id, []).append(plan)
        store.save_plan(plan)
        if "tracking" in holder:
            holder["tracking"].set_operations(airspace.operations.values())

    def on_operation(op: Operation) -> None:
        store.save_operation(op)

    def on_geofence(g: Geofence, active: bool) -> None:
        geofence_history[g.id] = g
        if active:
            store.save_geofence(g)
        else:
            store.deactivate_geofence(g.id)

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

    async def tracking_hazard(h: HazardReport) -> None:
        usm.on_hazard(h)

    tracking = TrackingService(
        tracker,
        clock,
        on_hazard=tracking_hazard,
        track_sink=store.write_tracks,
        ingest_delay_s=settings.tracking.ingest_delay_s,
    )
    holder["tracking"] = tracking

    def snapshot(t_s: float) -> Any:
        return airspace.snapshot(t_s, tracking.snapshot)

    monitor = Monitor(frame, settings.monitoring, id_prefix=id_prefix)
    monitoring = MonitoringService(
        monitor, snapshot, clock, usm.on_threats, period_s=settings.monitoring.period_s
    )
    td = TacticalDeconfliction(frame, settings.deconfliction, settings.monitoring)
    em = EmergencyManager(frame, settings.emergency, td, settings.monitoring)

    async def on_decision(decision: Decision) -> None:
        await apply_decision(usm, decision, store)

    def em_snapshot(t_s: float) -> Any:
        # EM/TD decide on the plans as they are being flown (re-timed by each UAS's delay),
        # the same timing Monitoring predicted the threat with
        return retime_snapshot(snapshot(t_s), frame)

    emergency = EmergencyService(em, em_snapshot, clock, on_decision)
    usm.attach_measurement_sink(tracking.submit, tracking.submit_lane)
    usm.attach_threat_sink(emergency.submit_threats)

    async def answer_sink(rec: Recommendation, accepted: bool) -> None:
        await emergency.submit_answer(rec.id, rec.version, accepted)

    usm.attach_answer_sink(answer_sink)
    hub = MavlinkHub(settings.mavlink, clock, usm)
    usm.attach_vehicles(hub)
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
        plan_history=plan_history,
        geofence_history=geofence_history,
    )


async def apply_decision(usm: Usm, decision: Decision, store: Persistence) -> None:
    """Carry an EM decision to the world through the USM. Order matters: geofences first so
    the operator sees why, then superseded proposals, then new recommendations."""
    for entry in decision.audit:
        store.record(entry)
    if decision.geofences:
        await usm.add_geofences(decision.geofences)
    for rec_id in decision.superseded:
        await usm.on_superseded(rec_id)
    for rec in decision.recommendations:
        await usm.on_recommendation(rec)
    for command in decision.commands:
        await usm.execute_command(command, reason="autonomous mode")
    for text in decision.escalations:
        await usm.escalate(text)
    for text in decision.warnings:
        usm.log_event("warning", text)


# ---- scenario runs ---------------------------------------------------------------------------


def vehicle_specs(
    scenario: Scenario,
    *,
    lead_s: float,
    gcs_host: str = "127.0.0.1",
    gcs_port: int = 14550,
    ephemeral_ports: bool = False,
) -> list[Any]:
    """Simulated vehicles of a scenario (``sitl.VehicleSpec``), PX4-like instance numbers,
    each preloaded with its filed plan as its mission (as if the pilot had uploaded it), with
    DO_CHANGE_SPEED per segment so it keeps the plan's timing, and the scenario's faults.
    ``lead_s`` is the simulated time between the fleet start and the scenario's t0.

    A vehicle appears in flight at its first waypoint at the filed start time plus its start
    delay (sitl's ``start_airborne``; silent until then): the paper's encounters are timed to
    the second, and a take-off and climb-out would shift every vehicle by a different amount.
    """
    from sitl import FaultKind, FaultSpec, MissionItemSpec, VehicleSpec

    frame = scenario.frame
    specs = []
    for i, v in enumerate(scenario.vehicles):
        wps = v.plan.waypoints
        items = []
        for j, w in enumerate(wps):
            speed = None
            if j > 0:
                a = wps[j - 1]
                e0, n0 = frame.point_to_local(a.lat_deg, a.lon_deg)
                e1, n1 = frame.point_to_local(w.lat_deg, w.lon_deg)
                dist = math.dist((e0, n0, a.alt_amsl_m), (e1, n1, w.alt_amsl_m))
                dt = w.t_s - a.t_s
                speed = dist / dt if dt > 0 and dist > 0 else None
            items.append(
                MissionItemSpec(
                    lat_deg=w.lat_deg, lon_deg=w.lon_deg, alt_amsl_m=w.alt_amsl_m, speed_mps=speed
                )
            )
        start_at = max(0.5, lead_s + (wps[0].t_s - scenario.t0_s) + v.start_delay_s)
        fastest = max([it.speed_mps or 0.0 for it in items] + [v.cruise_speed_mps])
        faults = [
            FaultSpec(
                kind=FaultKind[_FAULTS[ev.kind]],
                at_s=lead_s + ev.at_s,
                duration_s=ev.duration_s,
                # a scenario's jamming strength in 0..1 is not a drift: use the default drift
                value=None
                if ev.kind is EventKind.GNSS_JAMMING and ev.value is not None and ev.value <= 1.0
                else ev.value,
            )
            for ev in scenario.events
            if ev.uas == v.operation_id and ev.kind in _FAULTS
        ]
        specs.append(
            VehicleSpec(
                instance=i,
                sys_id=int(v.sys_id) if v.sys_id is not None else i + 1,
                kind=v.vehicle_kind.value,
                autopilot=v.autopilot.value if v.autopilot.value == "ardupilot" else "px4",
                home_lat_deg=v.home.lat_deg,
                home_lon_deg=v.home.lon_deg,
                home_alt_amsl_m=v.home.alt_amsl_m,
                cruise_speed_mps=v.cruise_speed_mps,
                max_speed_mps=max(fastest * 1.2, v.cruise_speed_mps + 2.0),
                climb_rate_mps=v.max_climb_rate_mps,
                mission=tuple(items),
                auto_start_at_s=start_at,
                start_airborne=True,
                # silent until it appears in flight: a tracker must not see a 100 m jump
                boot_at_s=start_at + 0.2,
                gcs_host=gcs_host,
                gcs_port=gcs_port,
                bind_port=0 if ephemeral_ports else None,
                tcp_port=0 if ephemeral_ports else None,
                faults=tuple(faults),
                battery_capacity_s=v.endurance_s or 1800.0,
                seed=i,
            )
        )
    return specs


_FAULTS = {
    EventKind.GNSS_JAMMING: "GNSS_JAMMING",
    EventKind.SPOOFING: "SPOOFING",
    EventKind.BATTERY_DROP: "BATTERY_DROP",
    EventKind.BATTERY_DRAIN: "BATTERY_DRAIN",
    EventKind.LINK_LOSS: "LINK_LOSS",
    EventKind.PACKET_LOSS: "PACKET_LOSS",
    EventKind.MOTOR_FAILURE: "MOTOR_FAILURE",
}


async def _play_alerts(rt: Runtime, scenario: Scenario, lead_s: float) -> None:
    """Stakeholder alerts of the scenario (e.g. a wildfire area) reach the USM at their time,
    as they would from MQTT."""
    alerts = sorted(
        (e for e in scenario.events if e.kind is EventKind.ALERT_AREA), key=lambda e: e.at_s
    )
    for ev in alerts:
        await rt.clock.sleep(max(0.0, ev.t_s - rt.clock.now_s()))
        rt.usm.on_hazard(_alert_hazard(ev))


def _alert_hazard(ev: ScenarioEvent) -> HazardReport:
    return HazardReport(
        kind=ThreatKind.ALERT_WARNING,
        t_s=ev.t_s,
        operation_id=ev.uas,
        area=ev.area,
        message=ev.reason or "stakeholder alert",
        source="scenario",
    )


async def _sample_tracks(rt: Runtime, period_s: float) -> None:
    """Record what the UTM knows, every ``period_s`` of clock time, for the report."""
    while True:
        for tid, t in rt.tracks().items():
            rt.samples.setdefault(tid, []).append(
                (t.t_s, t.lat_deg, t.lon_deg, t.alt_amsl_m, t.east_m, t.north_m)
            )
        await rt.clock.sleep(period_s)


async def run_scenario(
    scenario_path: Path,
    settings: Settings,
    options: RunOptions,
    *,
    on_runtime: Callable[[Runtime], Awaitable[None]] | None = None,
) -> dict[str, Any]:
    """Run one scenario end to end and return (and write) its report."""
    from gcs_utm.scenario import load_any

    lead_s = options.lead_s if options.lead_s is not None else 20.0
    start_utc = math.floor(time.time())
    clock = ScaledClock(options.speed, start_utc_s=start_utc)
    scenario = load_any(scenario_path, t0_s=start_utc + lead_s)
    if scenario.safety_distance_m is not None:
        # the scenario was written for one 3D safety distance (GAUSS safetyDistance)
        settings = replace(settings, monitoring=scenario.monitoring_for(settings.monitoring))
        _log.info(
            "%s: separation is the scenario's 3D safety distance of %.0f m",
            scenario.name,
            scenario.safety_distance_m,
        )
    options.out_dir.mkdir(parents=True, exist_ok=True)
    db_path = options.out_dir / f"{scenario.name}.sqlite"
    for suffix in ("", "-wal", "-shm"):
        Path(str(db_path) + suffix).unlink(missing_ok=True)
    store = Persistence(StoreWriter(db_path, settings.store))
    rt = build_runtime(settings, clock, scenario.frame, store)
    recorder = record_links(rt.hub, options.record_dir)
    rt.airspace.load(scenario.operations, scenario.geofences)
    for op in scenario.operations:
        store.save_operation(op)
        store.save_plan(op.plan)
        rt.plan_history.setdefault(op.id, []).append(op.plan)
    for g in scenario.geofences:
        store.save_geofence(g)
        rt.geofence_history[g.id] = g
    rt.tracking.set_operations(scenario.operations)

    duration_s = options.duration_s or scenario.duration_s
    end_t_s = scenario.t0_s + duration_s
    fleet = None
    link = options.link or (
        "udpin:127.0.0.1:0" if not options.external else settings.mavlink.links[0]
    )
    await rt.hub.add_link(link)
    gcs_port = rt.hub.local_port(link) if hasattr(rt.hub, "local_port") else 14550
    if not options.external:
        from sitl import Fleet, SimTime

        fleet = Fleet(
            vehicle_specs(scenario, lead_s=lead_s, gcs_port=gcs_port, ephemeral_ports=True),
            SimTime(options.speed, start_utc_s=start_utc, start_mono_s=clock.start_mono_s),
        )

    operators = _operators(rt, options)
    app = None
    if options.operator == OperatorMode.DASHBOARD and not options.headless:
        from gcs_utm.dashboard.tui import DashboardApp

        app = DashboardApp(
            rt.usm,
            rt.tracks,
            refresh_s=settings.dashboard.refresh_s,
            operator=settings.dashboard.operator,
            minima=_minima(settings),
        )
        rt.usm.attach_operator(app)
    for op_port in operators:
        rt.usm.attach_operator(op_port)
    gateway = None
    if options.mqtt or settings.mqtt.enabled:
        from gcs_utm.services.mqtt_gateway import MqttGateway

        gateway = MqttGateway(rt.usm, settings.mqtt, tracks=rt.tracks)
        rt.usm.attach_operator(gateway)
        rt.usm.attach_threat_sink(gateway.on_threats)
        rt.usm.attach_geofence_listener(gateway.on_geofences)

    wall0 = time.perf_counter()
    quit_requested = False
    try:
        async with contextlib.AsyncExitStack() as stack:
            if fleet is not None:
                await stack.enter_async_context(fleet)
            if on_runtime is not None:
                await on_runtime(rt)
            async with asyncio.TaskGroup() as tg:
                tasks = [
                    tg.create_task(rt.tracking.run(), name="tracking"),
                    tg.create_task(rt.monitoring.run(), name="monitoring"),
                    tg.create_task(rt.emergency.run(), name="emergency"),
                    tg.create_task(rt.usm.run(), name="usm"),
                    tg.create_task(_play_alerts(rt, scenario, lead_s), name="alerts"),
                    tg.create_task(_sample_tracks(rt, 0.5), name="samples"),
                    tg.create_task(rt.surveillance.run(), name="adsb"),
                ]
                if options.headless:
                    tasks.append(tg.create_task(_headless_status(rt), name="status"))
                tasks += [tg.create_task(o.run(), name="line") for o in _lines(operators)]
                if gateway is not None:
                    tasks.append(tg.create_task(gateway.run(), name="mqtt"))
                dash: asyncio.Task[Any] | None = None
                if app is not None:
                    dash = tg.create_task(app.run_async(), name="dashboard")
                    tasks.append(dash)
                await _until(rt.clock, end_t_s, app, dash)
                quit_requested = app is not None and app.quit_requested
                for t in tasks:
                    t.cancel()
    finally:
        await rt.usm.drain()
        await rt.usm.close()
        await rt.hub.close()
        if recorder is not None:
            recorder.close()
        wall_s = time.perf_counter() - wall0
    report = build_report(
        rt,
        scenario,
        wall_s=wall_s,
        speed=options.speed,
        vehicles=fleet.vehicles if fleet is not None else (),
    )
    report["operator_quit"] = quit_requested
    store.close()
    path = options.out_dir / f"{scenario.name}.json"
    path.write_text(json.dumps(report, indent=1))
    report["report_path"] = str(path)
    if options.figures:
        from gcs_utm.dashboard.plot import export_all

        export_all(report, options.out_dir, stem=scenario.name)
    return report


async def _until(
    clock: Clock, end_t_s: float, app: Any, dashboard: asyncio.Task[Any] | None
) -> None:
    """Run until the scenario's end, or until the operator quits the dashboard."""
    while clock.now_s() < end_t_s:
        if dashboard is not None and dashboard.done():
            return
        await clock.sleep(min(1.0, max(0.05, end_t_s - clock.now_s())))
    if app is not None:
        app.exit()


def _minima(settings: Settings) -> Minima:
    mon = settings.monitoring
    return Minima(horizontal_m=mon.separation_horizontal_m, vertical_m=mon.separation_vertical_m)


def _lines(operators: list[Any]) -> list[LinePrompt]:
    return [o for o in operators if isinstance(o, LinePrompt)]


def _operators(rt: Runtime, options: RunOptions) -> list[Any]:
    ops: list[Any] = []
    minima = _minima(rt.settings)
    if options.operator == OperatorMode.LINE:
        ops.append(LinePrompt(rt.usm, rt.tracks, minima=minima))
    elif options.headless or options.operator != OperatorMode.DASHBOARD:
        mqtt = options.mqtt or rt.settings.mqtt.enabled
        by = options.operator if options.operator != OperatorMode.NONE else ""
        by = by or ("MQTT (remote pilot station)" if mqtt else "")
        ops.append(HeadlessView(rt.usm, rt.tracks, answered_by=by, minima=minima))
    if options.operator in (OperatorMode.AUTO_ACCEPT, OperatorMode.AUTO_REJECT):
        ops.append(
            AutoOperator(
                rt.usm.answer,
                rt.clock,
                decision=PilotDecision.ACCEPT
                if options.operator == OperatorMode.AUTO_ACCEPT
                else PilotDecision.REJECT,
                delay_s=rt.settings.dashboard.auto_answer_delay_s,
                reject_first=options.reject_first,
            )
        )
    return ops


async def _headless_status(rt: Runtime) -> None:
    view = HeadlessView(rt.usm, rt.tracks)
    while True:
        await asyncio.sleep(rt.settings.dashboard.headless_status_s)
        view.status()


# ---- report ----------------------------------------------------------------------------------


def _rel(t_s: float | None, t0: float) -> float | None:
    return None if t_s is None else round(t_s - t0, 3)


def _plan_json(plan: FlightPlan, t0: float) -> dict[str, Any]:
    return {
        "version": plan.version,
        "reason": plan.reason,
        "waypoints": [
            [w.lat_deg, w.lon_deg, round(w.alt_amsl_m, 2), round(w.t_s - t0, 3)]
            for w in plan.waypoints
        ],
    }


def _geofence_json(g: Geofence, t0: float) -> dict[str, Any]:
    out: dict[str, Any] = {
        "id": g.id,
        "shape": g.shape.value,
        "min_alt_amsl_m": g.min_alt_amsl_m,
        "max_alt_amsl_m": g.max_alt_amsl_m,
        "start_s": _rel(g.start_t_s, t0),
        "end_s": _rel(g.end_t_s, t0),
        "kind": g.kind.value,
        "reason": g.reason,
        "exempt": list(g.exempt),
    }
    if g.shape is GeofenceShape.CYLINDER and g.center is not None:
        out["center"] = {"lat_deg": g.center.lat_deg, "lon_deg": g.center.lon_deg}
        out["radius_m"] = g.radius_m
    else:
        out["vertices"] = [{"lat_deg": v.lat_deg, "lon_deg": v.lon_deg} for v in g.vertices]
    return out


def _threat_json(t: Threat, t0: float) -> dict[str, Any]:
    return {
        "id": t.id,
        "kind": t.kind.value,
        "uas": list(t.uas_ids),
        "status": t.status.value,
        "detected_at_s": _rel(t.detected_at_s, t0),
        "predicted_event_at_s": _rel(t.predicted_event_at_s, t0),
        "geofence": t.geofence_id,
        "closest_approach_m": t.closest_approach_m,
        "closest_approach_at_s": _rel(t.closest_approach_t_s, t0),
        "position": None
        if t.position is None
        else {
            "lat_deg": t.position.lat_deg,
            "lon_deg": t.position.lon_deg,
            "alt_amsl_m": t.position.alt_amsl_m,
        },
        "message": t.message,
    }


def build_report(
    rt: Runtime, scenario: Scenario, *, wall_s: float, speed: float, vehicles: Any = ()
) -> dict[str, Any]:
    t0 = scenario.t0_s
    ops = rt.airspace.operations
    sep_h = rt.settings.monitoring.separation_horizontal_m
    sep_v = rt.settings.monitoring.separation_vertical_m
    delays = {v.operation_id: v.start_delay_s for v in scenario.vehicles}
    report: dict[str, Any] = {
        "scenario": scenario.name,
        "description": scenario.description,
        "speed": speed,
        "wall_clock_s": round(wall_s, 3),
        "origin": {
            "lat_deg": scenario.frame.origin_lat_deg,
            "lon_deg": scenario.frame.origin_lon_deg,
            "ground_elevation_amsl_m": scenario.frame.ground_elevation_amsl_m,
        },
        "separation_minimum": {
            "mode": rt.settings.monitoring.separation_mode,
            "horizontal_m": sep_h,
            "vertical_m": sep_v,
            "safety_distance_m": rt.settings.monitoring.safety_distance_m,
        },
        "operations": [
            {
                "id": op.id,
                "priority": op.priority,
                "conops": op.conops,
                "vehicle": op.vehicle_kind.value,
                "state": op.state.value,
                "flight_geometry_m": op.flight_geometry_m,
                "operational_volume_m": op.operational_volume_m,
                "start_delay_s": delays.get(op.id, 0.0),
                "plans": [_plan_json(p, t0) for p in rt.plan_history.get(op.id, [op.plan])],
            }
            for op in ops.values()
        ],
        "geofences": [_geofence_json(g, t0) for g in rt.geofence_history.values()],
        "threats": [_threat_json(t, t0) for t in rt.usm.threat_log],
        "recommendations": [],
        "tracks": {
            tid: [[round(s[0] - t0, 3), s[1], s[2], round(s[3], 2)] for s in samples]
            for tid, samples in rt.samples.items()
        },
        "telemetry": {k: v.as_dict(speed) for k, v in rt.usm.telemetry.items()},
        "counters": dict(rt.usm.counters),
        "adsb": rt.surveillance.report(rt.hub.adsb_relay.counters),
    }
    for record in rt.usm.recommendations.values():
        rec = record.rec
        alts = []
        options = ([rec.selected] if rec.selected is not None else []) + list(rec.alternatives)
        for i, alt in enumerate(options):
            alts.append(
                {
                    "maneuver": alt.maneuver.value,
                    "cost": round(alt.cost, 4),
                    "risk": round(alt.risk, 4),
                    "selected": i == 0 and rec.selected is not None,
                    "waypoints": [] if alt.plan is None else _plan_json(alt.plan, t0)["waypoints"],
                }
            )
        report["recommendations"].append(
            {
                "id": rec.id,
                "version": rec.version,
                "uas": rec.operation_id,
                "threat_kind": rec.threat_kind.value,
                "maneuver": rec.selected.maneuver.value
                if rec.selected is not None
                else (rec.command.kind.value if rec.command is not None else None),
                "cost": None if rec.selected is None else round(rec.selected.cost, 4),
                "risk": None if rec.selected is None else round(rec.selected.risk, 4),
                "latency_ms": round(record.latency_ms, 3),
                "created_at_s": _rel(rec.created_t_s, t0),
                "deadline_at_s": _rel(rec.deadline_t_s, t0),
                "decision": record.decision or rec.state.value,
                "answered_by": record.answered_by,
                "answered_via": record.answered_via,
                "chosen_alternative_index": record.chosen_index,
                "state": rec.state.value,
                "uploaded": record.uploaded,
                "verified": record.verified,
                "error": record.error,
                # every version's proposal and state change, so a rejected or expired version
                # replaced by a newer one under the same id stays visible
                "history": [[_rel(t, t0), text] for t, text in record.history],
                "alternatives": alts,
            }
        )
    report["separation"] = _separation(rt, ops, sep_h, sep_v)
    report["geofence_intrusions"] = _intrusions(rt, t0)
    if vehicles:
        report["truth"] = _truth(vehicles, scenario, rt)
    return report


def _separation(
    rt: Runtime, ops: dict[OperationId, Operation], sep_h: float, sep_v: float
) -> list[dict[str, Any]]:
    """Minimum achieved distances per UAS pair, from the tracks sampled during the run at the
    same sample instants (both tracks' states are at most one sample period apart)."""
    out = []
    ids = sorted(i for i in rt.samples if OperationId(i) in ops)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            sa = {round(s[0], 1): s for s in rt.samples[a]}
            best_h = best_v = best_3d = math.inf
            loss = False
            for key, s in sa.items():
                match = _nearest(rt.samples[b], key)
                if match is None:
                    continue
                dh = math.hypot(s[4] - match[4], s[5] - match[5])
                dv = abs(s[3] - match[3])
                best_h = min(best_h, dh)
                best_v = min(best_v, dv) if dh < sep_h * 3 else best_v
                best_3d = min(best_3d, math.hypot(dh, dv))
                loss = loss or _is_loss(rt, dh, dv, ops[OperationId(a)], ops[OperationId(b)])
            out.append(
                {
                    "pair": [a, b],
                    "min_horizontal_m": None if math.isinf(best_h) else round(best_h, 2),
                    "min_vertical_when_close_m": None if math.isinf(best_v) else round(best_v, 2),
                    "min_distance_m": None if math.isinf(best_3d) else round(best_3d, 2),
                    "loss_of_separation": loss,
                }
            )
    return out


def _is_loss(rt: Runtime, dh: float, dv: float, a: Operation, b: Operation) -> bool:
    """Loss of separation as Monitoring defines it (effective minima of the pair's
    operational volumes; cylinder or sphere): :func:`gcs_utm.core.monitoring.loss.is_loss`."""
    from gcs_utm.core.monitoring.loss import is_loss

    return is_loss(rt.settings.monitoring, dh, dv, a.operational_volume_m, b.operational_volume_m)


def _nearest(samples: Sequence[tuple[float, ...]], t_s: float) -> tuple[float, ...] | None:
    import bisect

    times = [s[0] for s in samples]
    i = bisect.bisect_left(times, t_s)
    best = None
    for j in (i - 1, i):
        if (
            0 <= j < len(samples)
            and abs(samples[j][0] - t_s) <= 0.6
            and (best is None or abs(samples[j][0] - t_s) < abs(best[0] - t_s))
        ):
            best = samples[j]
    return best


def _intrusions(rt: Runtime, t0: float) -> list[dict[str, Any]]:
    """Actual (not predicted) geofence intrusions of the tracks flown."""
    out = []
    for tid, samples in rt.samples.items():
        for g in rt.geofence_history.values():
            lf = localise(g, rt.frame)
            if not g.applies_to(tid):
                continue
            inside = [s for s in samples if g.active_at(s[0]) and _inside(lf, s[4], s[5], s[3])]
            if inside:
                out.append(
                    {
                        "uas": tid,
                        "geofence": g.id,
                        "first_at_s": round(inside[0][0] - t0, 3),
                        "samples_inside": len(inside),
                    }
                )
    return out


def _inside(lf: Any, east_m: float, north_m: float, alt_amsl_m: float) -> bool:
    """Is a point inside a localised geofence (altitude band, then cylinder or polygon)?"""
    if not lf.z_lo <= alt_amsl_m <= lf.z_hi:
        return False
    if lf.center is not None:
        return bool(math.hypot(east_m - lf.center[0], north_m - lf.center[1]) <= lf.radius_m)
    import numpy as np

    inside = points_in_edges(np.array([east_m]), np.array([north_m]), lf.edges)
    return bool(inside[0])


def _truth(vehicles: Any, scenario: Scenario, rt: Runtime) -> dict[str, Any]:
    """Ground truth from the simulated vehicles (their true positions, not the tracks)."""
    by_sys = {int(v.sys_id): v for v in vehicles}
    ops = {int(op.sys_id): op.id for op in scenario.operations if op.sys_id is not None}
    op_of = {int(op.sys_id): op for op in scenario.operations if op.sys_id is not None}
    out: dict[str, Any] = {"pairs": []}
    ids = sorted(s for s in by_sys if s in ops)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            ha = by_sys[a].position_history
            hb = by_sys[b].position_history
            best = math.inf
            loss = False
            j = 0
            for t, lat, lon, alt in ha:
                while j + 1 < len(hb) and hb[j + 1][0] <= t:
                    j += 1
                if not hb or abs(hb[j][0] - t) > 1.0:
                    continue
                ea, na = rt.frame.point_to_local(lat, lon)
                eb, nb = rt.frame.point_to_local(hb[j][1], hb[j][2])
                dh = math.hypot(ea - eb, na - nb)
                dv = abs(alt - hb[j][3])
                best = min(best, math.hypot(dh, dv))
                loss = loss or _is_loss(rt, dh, dv, op_of[a], op_of[b])
            out["pairs"].append(
                {
                    "pair": [ops[a], ops[b]],
                    "min_distance_m": None if math.isinf(best) else round(best, 2),
                    "loss_of_separation": loss,
                }
            )
    return out


# ---- serve -----------------------------------------------------------------------------------


async def serve(
    settings: Settings,
    *,
    db_path: Path,
    operator: str,
    headless: bool,
    stop: asyncio.Event | None = None,
    on_runtime: Callable[[Runtime], Awaitable[None]] | None = None,
    speed: float = 1.0,
    record_dir: Path | None = None,
) -> int:
    """Long-running service: links from config, persistent store; restart resumes. Runs until
    SIGINT/SIGTERM (or ``stop`` is set). ``speed`` > 1 matches SITL vehicles running faster
    than real time: the service's clock then advances ``speed`` simulated seconds per second."""
    clock: Clock = RealClock() if speed == 1.0 else ScaledClock(speed)
    frame = LocalFrame(
        settings.airspace.origin_lat_deg,
        settings.airspace.origin_lon_deg,
        settings.airspace.ground_elevation_amsl_m,
    )
    reader = Store(db_path)
    operations = reader.load_operations()
    geofences = reader.load_geofences(active_only=True)
    reader.close()
    store = Persistence(StoreWriter(db_path, settings.store))
    rt = build_runtime(settings, clock, frame, store)
    recorder = record_links(rt.hub, record_dir)
    rt.airspace.load(operations, geofences)
    rt.tracking.set_operations(operations)
    _log.info(
        "resumed %d operations and %d geofences from %s", len(operations), len(geofences), db_path
    )
    for link in settings.mavlink.links:
        await rt.hub.add_link(link)
    options = RunOptions(headless=headless, operator=operator)
    operators = _operators(rt, options)
    for op_port in operators:
        rt.usm.attach_operator(op_port)
    app = None
    if operator == OperatorMode.DASHBOARD and not headless:
        from gcs_utm.dashboard.tui import DashboardApp

        app = DashboardApp(
            rt.usm, rt.tracks, refresh_s=settings.dashboard.refresh_s, minima=_minima(settings)
        )
        rt.usm.attach_operator(app)
    gateway = None
    if settings.mqtt.enabled:
        from gcs_utm.services.mqtt_gateway import MqttGateway

        gateway = MqttGateway(rt.usm, settings.mqtt, tracks=rt.tracks)
        rt.usm.attach_operator(gateway)
        rt.usm.attach_threat_sink(gateway.on_threats)
        rt.usm.attach_geofence_listener(gateway.on_geofences)
    stop = stop or asyncio.Event()
    if on_runtime is not None:
        await on_runtime(rt)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    try:
        async with asyncio.TaskGroup() as tg:
            tasks = [
                tg.create_task(rt.tracking.run(), name="tracking"),
                tg.create_task(rt.monitoring.run(), name="monitoring"),
                tg.create_task(rt.emergency.run(), name="emergency"),
                tg.create_task(rt.usm.run(), name="usm"),
                tg.create_task(rt.surveillance.run(), name="adsb"),
            ]
            if headless:
                tasks.append(tg.create_task(_headless_status(rt), name="status"))
            tasks += [tg.create_task(o.run(), name="line") for o in _lines(operators)]
            if gateway is not None:
                tasks.append(tg.create_task(gateway.run(), name="mqtt"))
            if app is not None:
                dash = tg.create_task(app.run_async(), name="dashboard")
                dash.add_done_callback(lambda _t: stop.set())
                tasks.append(dash)
            await stop.wait()
            for t in tasks:
                t.cancel()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.remove_signal_handler(sig)
        await rt.usm.close()
        await rt.hub.close()
        if recorder is not None:
            recorder.close()
        store.close()
    print("gcs-utm serve: stopped", file=sys.stderr)
    return 0
