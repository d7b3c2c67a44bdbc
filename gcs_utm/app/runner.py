"""Scenario runs: the scenario's simulated vehicles (``sitl``) and the UTM service on one
clock, the scenario's events played at their time, and the report written at the end.

Speed: ``RunOptions.speed`` is a speed-up factor of the wall clock (vehicles and UTM share
the factor and the monotonic anchor), or ``math.inf`` for fast time: the run happens on a
:class:`gcs_utm.clock.FastTimeLoop` whose time jumps to the next timer as soon as nothing is
left to compute, and one :class:`gcs_utm.clock.LoopClock` is the clock of both the UTM and
the vehicles. MAVLink still goes over loopback UDP. Fast time starts at a fixed simulated
epoch (``FAST_TIME_EPOCH_UTC_S``) so that two runs of one scenario compute on the same
numbers and give the same report (wall-clock fields aside).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gcs_utm.clock import Clock, FastTimeLoop, LoopClock, ScaledClock
from gcs_utm.messages import HazardReport
from gcs_utm.model import ThreatKind
from gcs_utm.scenario import Scenario
from gcs_utm.scenario.types import EventKind, ScenarioEvent
from gcs_utm.services.recorder import check_folder, record_links
from gcs_utm.settings import Settings
from gcs_utm.store import StoreWriter

from .fly import FlyOutcome, fly_scenario
from .report import Report, build_report
from .wiring import (
    FrontendOptions,
    Frontends,
    OperatorMode,
    Persistence,
    Runtime,
    attach_frontends,
    build_runtime,
    start_service_tasks,
)

if TYPE_CHECKING:
    from sitl import Fleet

_log = logging.getLogger(__name__)

FAST_TIME_EPOCH_UTC_S = 1_767_225_600.0
"""Simulated UTC of a fast-time run's start (2026-01-01T00:00:00Z): fixed, so that every
absolute time of a run, and every rounding of it, is the same from run to run."""

DEFAULT_LEAD_S = 20.0
"""Simulated seconds between the vehicles' start and the scenario's t0 (links up, tracks
established before the first planned event)."""

SAMPLE_PERIOD_S = 0.5
"""Clock seconds between two samples of the UTM's tracks for the report."""


@dataclass(frozen=True, slots=True, kw_only=True)
class RunOptions:
    """Options of ``gcs-utm run`` (and ``demo``, ``eval``). ``speed`` is a speed-up factor,
    or ``math.inf`` for fast time (``--speed max``)."""

    speed: float = 1.0
    headless: bool = False
    quiet: bool = False
    operator: str = OperatorMode.DASHBOARD
    reject_first: int = 0
    external: bool = False
    fly: bool = False  # with external: upload, arm, take off and start each plan (fly.py)
    link: str | None = None
    mqtt: bool = False
    out_dir: Path = Path("runs")
    duration_s: float | None = None
    figures: bool = True
    lead_s: float | None = None
    record_dir: Path | None = None  # record every MAVLink link as a .tlog here

    def __post_init__(self) -> None:
        if not self.speed > 0.0:
            raise ValueError(f"RunOptions.speed: expected > 0 or inf, got {self.speed}")
        if self.fast_time and self.external:
            raise ValueError(
                "RunOptions: fast time (speed max) runs the built-in vehicles on the UTM's "
                "clock; external autopilots run on their own clock (use a speed factor)"
            )
        if self.fly and not self.external:
            raise ValueError(
                "RunOptions: fly makes external autopilots fly the plans; the built-in "
                "vehicles already fly them (add external)"
            )

    @property
    def fast_time(self) -> bool:
        return math.isinf(self.speed)


def report_path(out_dir: Path, scenario_name: str) -> Path:
    """Where ``run_scenario`` writes the JSON report of a scenario."""
    return out_dir / f"{scenario_name}.json"


def vehicle_specs(
    scenario: Scenario,
    *,
    lead_s: float,
    gcs_host: str = "127.0.0.1",
    gcs_port: int = 14550,
    ephemeral_ports: bool = False,
    fast_time: bool = False,
) -> list[Any]:
    """Simulated vehicles of a scenario (``sitl.VehicleSpec``), PX4-like instance numbers,
    each preloaded with its filed plan as its mission (as if the pilot had uploaded it), with
    DO_CHANGE_SPEED per segment so it keeps the plan's timing, and the scenario's faults.
    ``lead_s`` is the simulated time between the fleet start and the scenario's t0.
    ``fast_time``: the vehicles run on a fast-time loop, where wall-clock stream caps would
    drop messages by how fast the machine is: lift them (each stream keeps its simulated rate).

    A vehicle appears in flight at its first waypoint at the filed start time plus its start
    delay (sitl's ``start_airborne``; silent until then): the paper's encounters are timed to
    the second, and a take-off and climb-out would shift every vehicle by a different amount.
    """
    from sitl import FaultKind, FaultSpec, MissionItemSpec, VehicleSpec

    frame = scenario.frame
    envelopes = {op.id: op.performance() for op in scenario.operations}
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
                # one envelope: the vehicle flies the speeds the UTM plans with
                min_airspeed_mps=envelopes[v.operation_id].min_speed_mps,
                max_speed_mps=envelopes[v.operation_id].max_speed_mps,
                climb_rate_mps=envelopes[v.operation_id].climb_rate_mps,
                descent_rate_mps=envelopes[v.operation_id].descent_rate_mps,
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
        if fast_time:
            specs[-1] = replace(specs[-1], max_real_stream_hz=math.inf)
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


_REPORTED = {
    EventKind.GNSS_JAMMING: ThreatKind.JAMMING_ATTACK,
    EventKind.SPOOFING: ThreatKind.SPOOFING_ATTACK,
}
"""Scenario faults an external vehicle cannot be made to suffer, but its RPA reports (the
GNSS status of a network identification message, adapters/mqtt/codec.py): with
``--external`` they reach the USM as that report at their time."""


def played_hazards(scenario: Scenario, *, external: bool) -> list[HazardReport]:
    """The hazards the run itself reports to the USM, in time order: the stakeholder alerts
    (e.g. a wildfire area), as they would come from MQTT; with ``external`` also the
    scenario's GNSS jamming and spoofing of a UAS (the built-in vehicles suffer those in
    their simulated receiver instead; a real autopilot in SITL has no such receiver fault)."""
    out = [_alert_hazard(e) for e in scenario.events if e.kind is EventKind.ALERT_AREA]
    if external:
        out += [
            HazardReport(
                kind=_REPORTED[e.kind],
                t_s=e.t_s,
                operation_id=e.uas,
                message=f"RPA reports {e.kind.value.replace('_', ' ')}"
                + (f": {e.reason}" if e.reason else ""),
                source="scenario",
            )
            for e in scenario.events
            if e.kind in _REPORTED and e.uas is not None
        ]
    return sorted(out, key=lambda h: h.t_s)


async def _play_hazards(rt: Runtime, hazards: list[HazardReport]) -> None:
    """Each of ``hazards`` reaches the USM at its time."""
    for h in hazards:
        await rt.clock.sleep(max(0.0, h.t_s - rt.clock.now_s()))
        rt.usm.on_hazard(h)


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


def _clocks(options: RunOptions) -> tuple[float, Clock, Any]:
    """(start UTC, the UTM's clock, the vehicles' clock) of a run."""
    if options.fast_time:
        loop = asyncio.get_running_loop()
        if not isinstance(loop, FastTimeLoop):
            raise RuntimeError(
                "fast time needs its own event loop: call run_scenario_blocking (or run "
                "run_scenario on a gcs_utm.clock.FastTimeLoop)"
            )
        clock = LoopClock(loop, FAST_TIME_EPOCH_UTC_S)
        return FAST_TIME_EPOCH_UTC_S, clock, clock
    from sitl import SimTime

    start_utc = math.floor(time.time())
    scaled = ScaledClock(options.speed, start_utc_s=start_utc)
    # one monotonic anchor for both clocks: separate anchors would show as a telemetry delay
    sim = SimTime(options.speed, start_utc_s=start_utc, start_mono_s=scaled.start_mono_s)
    return start_utc, scaled, sim


def _load(scenario_path: Path, settings: Settings, t0_s: float) -> tuple[Scenario, Settings]:
    from gcs_utm.scenario import load_any

    scenario = load_any(scenario_path, t0_s=t0_s)
    if scenario.safety_distance_m is not None:
        # the scenario was written for one 3D safety distance (GAUSS safetyDistance)
        settings = replace(settings, monitoring=scenario.monitoring_for(settings.monitoring))
        _log.info(
            "%s: separation is the scenario's 3D safety distance of %.0f m",
            scenario.name,
            scenario.safety_distance_m,
        )
    return scenario, settings


def _open_store(options: RunOptions, scenario: Scenario, settings: Settings) -> Persistence:
    options.out_dir.mkdir(parents=True, exist_ok=True)
    db_path = options.out_dir / f"{scenario.name}.sqlite"
    for suffix in ("", "-wal", "-shm"):
        Path(str(db_path) + suffix).unlink(missing_ok=True)
    return Persistence(StoreWriter(db_path, settings.store))


def _file_scenario(rt: Runtime, scenario: Scenario) -> None:
    """The scenario's operations and geofences, as if filed before the run."""
    rt.airspace.load(scenario.operations, scenario.geofences)
    for op in scenario.operations:
        rt.store.save_operation(op)
        rt.store.save_plan(op.plan)
        rt.plan_history.setdefault(op.id, []).append(op.plan)
    for g in scenario.geofences:
        rt.store.save_geofence(g)
        rt.geofence_history[g.id] = g
    rt.tracking.set_operations(scenario.operations)


async def run_scenario(
    scenario_path: Path,
    settings: Settings,
    options: RunOptions,
    *,
    on_runtime: Callable[[Runtime], Awaitable[None]] | None = None,
) -> Report:
    """Run one scenario end to end, write its report (``report_path``) and figures, and
    return the report. Fast time (``options.speed`` = inf) needs a :class:`FastTimeLoop`:
    use :func:`run_scenario_blocking`."""
    lead_s = options.lead_s if options.lead_s is not None else DEFAULT_LEAD_S
    start_utc, clock, sim_clock = _clocks(options)
    scenario, settings = _load(scenario_path, settings, start_utc + lead_s)
    if options.record_dir is not None:  # refused before anything starts (RecordError)
        check_folder(options.record_dir, settings.record)
    rt = build_runtime(settings, clock, scenario.frame, _open_store(options, scenario, settings))
    rt.close_in_threads = not options.fast_time  # a fast-time loop does not wait for threads
    async with rt:  # whatever fails from here on, what was started is torn down
        rt.recorder = record_links(
            rt.hub,
            options.record_dir,
            settings.record,
            surveillance=rt.surveillance,
            on_failure=lambda text: rt.usm.log_event("recording", text),
        )
        _file_scenario(rt, scenario)
        end_t_s = scenario.t0_s + (options.duration_s or scenario.duration_s)
        link = options.link or (
            "udpin:127.0.0.1:0" if not options.external else settings.mavlink.links[0]
        )
        await rt.hub.add_link(link)
        fleet = _fleet(rt, scenario, options, link=link, lead_s=lead_s, sim_clock=sim_clock)
        frontends = attach_frontends(
            rt,
            FrontendOptions(
                operator=options.operator,
                headless=options.headless,
                quiet=options.quiet,
                mqtt=options.mqtt,
                reject_first=options.reject_first,
            ),
        )
        wall0 = time.perf_counter()
        flown: list[FlyOutcome] = []
        try:
            async with contextlib.AsyncExitStack() as stack:
                if fleet is not None:
                    await stack.enter_async_context(fleet)
                if on_runtime is not None:
                    await on_runtime(rt)
                quit_requested = await _serve(
                    rt, frontends, scenario, options, end_t_s=end_t_s, flown=flown
                )
        finally:
            await rt.close()
            wall_s = time.perf_counter() - wall0
    report = build_report(
        rt,
        scenario,
        wall_s=wall_s,
        speed="max" if options.fast_time else options.speed,
        vehicles=fleet.vehicles if fleet is not None else (),
        operator_quit=quit_requested,
    )
    _write_outputs(report, scenario, options, flown)
    return report


def _fleet(
    rt: Runtime,
    scenario: Scenario,
    options: RunOptions,
    *,
    link: str,
    lead_s: float,
    sim_clock: Any,
) -> Fleet | None:
    """The scenario's simulated vehicles (sitl), talking to ``link``; None with
    ``--external`` (real autopilots)."""
    if options.external:
        return None
    from sitl import Fleet

    specs = vehicle_specs(
        scenario,
        lead_s=lead_s,
        gcs_port=rt.hub.local_port(link),
        ephemeral_ports=True,
        fast_time=options.fast_time,
    )
    return Fleet(specs, sim_clock)


async def _serve(
    rt: Runtime,
    frontends: Frontends,
    scenario: Scenario,
    options: RunOptions,
    *,
    end_t_s: float,
    flown: list[FlyOutcome],
) -> bool:
    """The service tasks, the scenario's alerts, track sampling and (``--fly``) the flights,
    until the scenario's end or the operator quits the dashboard; True when they quit."""
    async with asyncio.TaskGroup() as tg:
        tasks = start_service_tasks(tg, rt, frontends)
        hazards = played_hazards(scenario, external=options.external)
        tasks.append(tg.create_task(_play_hazards(rt, hazards), name="alerts"))
        tasks.append(tg.create_task(_sample_tracks(rt, SAMPLE_PERIOD_S), name="samples"))
        if options.fly:
            # the plan version current at upload: a resolution accepted before the
            # take-off is flown, not overwritten by the filed plan
            fly = fly_scenario(
                rt.hub,
                rt.clock,
                scenario,
                flown,
                current_plan=lambda op_id: rt.airspace.operation(op_id).plan,
            )
            tasks.append(tg.create_task(fly, name="fly"))
        dash = next((t for t in tasks if t.get_name() == "dashboard"), None)
        await _until(rt.clock, end_t_s, dash)
        if frontends.dashboard is not None and dash is not None and not dash.done():
            frontends.dashboard.exit()
        quit_requested = frontends.dashboard is not None and frontends.dashboard.quit_requested
        for t in tasks:
            t.cancel()
    return quit_requested


def _write_outputs(
    report: Report, scenario: Scenario, options: RunOptions, flown: list[FlyOutcome]
) -> None:
    """The report's JSON (with the flights of ``--fly``) and, with ``figures``, its plots."""
    data = report.to_json()
    if options.fly:
        data["fly"] = [o.to_json() for o in flown]
    report_path(options.out_dir, scenario.name).write_text(json.dumps(data, indent=1))
    if options.figures:
        from gcs_utm.dashboard.plot import export_all

        export_all(data, options.out_dir, stem=scenario.name)


def run_scenario_blocking(
    scenario_path: Path,
    settings: Settings,
    options: RunOptions,
    *,
    on_runtime: Callable[[Runtime], Awaitable[None]] | None = None,
) -> Report:
    """:func:`run_scenario` on an event loop of its own: a :class:`FastTimeLoop` in fast
    time, an ordinary one otherwise."""
    factory = FastTimeLoop if options.fast_time else None
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(run_scenario(scenario_path, settings, options, on_runtime=on_runtime))


async def _until(clock: Clock, end_t_s: float, dashboard: asyncio.Task[Any] | None) -> None:
    """Run until the scenario's end, or until the operator quits the dashboard."""
    while clock.now_s() < end_t_s:
        if dashboard is not None and dashboard.done():
            return
        await clock.sleep(min(1.0, max(0.05, end_t_s - clock.now_s())))
