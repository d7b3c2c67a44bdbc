"""``gcs-utm replay FILE.tlog [--speed N|max] [--report OUT.json]``: a recorded ``.tlog`` run
through the same pipeline as a live link (MAVLink telemetry decoder -> Tracking ->
Monitoring), with a progress bar on stderr and a JSON report.

Pipeline (:class:`ReplayPipeline`, sans-IO: feed it ``(record t_s, packet)``):

- every record's packet is parsed by the MAVLink adapter's parser
  (:class:`adapters.mavlink.wire.Parser`) and dispatched, per (sysid, compid), to the adapter's
  per-vehicle telemetry state (:class:`adapters.mavlink.vehicle.VehicleState`), exactly as the
  hub does on a live link; ground stations (HEARTBEAT autopilot ``MAV_AUTOPILOT_INVALID``) are
  not vehicles;
- the **record time is the capture time** (and the receipt time) of every measurement: the
  vehicle-clock mapping of a live link is replaced, because a tlog's record times are the only
  clock all vehicles in it share;
- the airspace frame's origin is the first position seen (its altitude is the frame's ground
  elevation); tracks are built by :class:`gcs_utm.core.tracking.Tracker`. Without operations
  every vehicle is a non-cooperative ``sysid:<n>`` track, and Monitoring (which watches
  *operations*: conformance, geofences, separation between operations, intruders near an
  operation) has nothing to raise. With a scenario (``--scenario``, its t0 = the first record
  time) its operations and geofences are loaded, vehicles are associated by sysid, and the
  scenario's frame is used;
- every ``period_s`` (1 s) of record time the measurements received since the last cycle are
  ingested as one batch (the reorder window), staleness is checked, and one monitoring cycle
  runs on the snapshot at the cycle time. A gap in the recording longer than
  ``_MAX_CATCH_UP_CYCLES`` periods is skipped instead of cycling through silence.

Bad input: corrupt records are skipped and counted by the tlog reader, bad frames by the
parser; a file without a single valid record is an error (:class:`ReplayError`).
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import logging
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adapters.mavlink import wire
from adapters.mavlink.adsb_relay import AdsbRelay
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.vehicle import VehicleInfo, VehicleState
from adapters.tlog import ReplayStats, TlogCounters, TlogReader, replay
from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.messages import HazardReport, LinkHealth, VehicleKey, VehicleStatus
from gcs_utm.model import (
    AirspaceSnapshot,
    Geofence,
    Measurement,
    Operation,
    OperationId,
    SysId,
    Threat,
    TrackId,
)
from gcs_utm.scenario import ScenarioError

_log = logging.getLogger(__name__)

MAV_AUTOPILOT_INVALID = 8  # a ground station or companion, not a vehicle
_MAX_CATCH_UP_CYCLES = 30  # beyond this many silent periods, jump to the next record
_PROGRESS_EVERY = 256  # records between progress-bar updates (rendering is not free)

_Handler = Callable[[VehicleState, wire.MavMsg, float, Any], object]
_HANDLERS: dict[int, _Handler] = {
    wire.HEARTBEAT: VehicleState.on_heartbeat,
    wire.GLOBAL_POSITION_INT: VehicleState.on_global_position,
    wire.GPS_RAW_INT: VehicleState.on_gps_raw,
    wire.SYS_STATUS: VehicleState.on_sys_status,
    wire.BATTERY_STATUS: VehicleState.on_battery_status,
    wire.MISSION_CURRENT: VehicleState.on_mission_current,
    wire.EXTENDED_SYS_STATE: VehicleState.on_extended_sys_state,
    wire.STATUSTEXT: VehicleState.on_statustext,
    wire.SYSTEM_TIME: VehicleState.on_system_time,
}


class ReplayError(ValueError):
    """A replay that cannot produce a report (missing file, no valid record)."""

    def __init__(self, path: Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


@dataclass(slots=True)
class _VehicleStats:
    sys_id: int
    comp_id: int
    messages: int = 0
    positions: int = 0
    first_t_s: float | None = None
    last_t_s: float | None = None
    first_position: tuple[float, float, float] | None = None
    last_position: tuple[float, float, float] | None = None


@dataclass(slots=True)
class _TrackStats:
    first_t_s: float
    last_t_s: float
    raw_updates: int
    last: tuple[float, float, float]  # east_m, north_m, alt_amsl_m
    last_wgs84: tuple[float, float, float]
    cooperative: bool
    distance_m: float = 0.0
    max_speed_mps: float = 0.0
    base_updates: int = 0

    @property
    def updates(self) -> int:
        return self.base_updates + self.raw_updates


@dataclass(slots=True)
class _ThreatStats:
    kind: str
    uas: tuple[str, ...]
    intruder: str | None
    first_t_s: float
    last_t_s: float
    cycles: int = 1
    closed_t_s: float | None = None
    min_closest_approach_m: float | None = None
    predicted_event_t_s: float | None = None
    message: str = ""


@dataclass(slots=True)
class _Counters:
    cycles: int = 0
    skipped_cycles: int = 0
    gcs_messages: int = 0
    handler_errors: int = 0
    measurements: int = 0
    rejected: dict[str, int] = field(default_factory=dict)


class ReplayPipeline:
    """Telemetry decoder + tracker + monitor over record time; see the module docstring."""

    def __init__(
        self,
        *,
        link: str = "tlog",
        mavlink: MavlinkConfig | None = None,
        tracking: TrackingConfig | None = None,
        monitoring: MonitoringConfig | None = None,
        period_s: float = 1.0,
        frame: LocalFrame | None = None,
        operations: Sequence[Operation] = (),
        geofences: Sequence[Geofence] = (),
    ) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s must be positive, got {period_s}")
        self.link = link
        self.mavlink = mavlink or MavlinkConfig()
        self.tracking = tracking or TrackingConfig()
        self.monitoring = monitoring or MonitoringConfig()
        self.period_s = period_s
        self.parser = wire.Parser()
        self.frame: LocalFrame | None = frame
        self.operations: dict[OperationId, Operation] = {op.id: op for op in operations}
        self.geofences = tuple(geofences)
        if self.operations and frame is None:
            raise ValueError("operations need the frame their plans are in")
        self.tracker: Tracker | None = None
        self.monitor: Monitor | None = None
        self.counters = _Counters()
        self.first_t_s: float | None = None
        self.last_t_s: float | None = None
        self.records = 0
        self.vehicles: dict[tuple[int, int], _VehicleStats] = {}
        self.infos: dict[tuple[int, int], VehicleInfo] = {}
        self.statuses: dict[int, VehicleStatus] = {}
        self.hazards: list[HazardReport] = []
        self.tracks: dict[TrackId, _TrackStats] = {}
        self.threats: dict[str, _ThreatStats] = {}
        self._states: dict[tuple[int, int], VehicleState] = {}
        self.adsb_relay = AdsbRelay()  # ADSB_VEHICLE -> ADS-B measurements, as on a live link
        self._pending: list[Measurement] = []
        self._t = 0.0
        self._next_cycle_t_s: float | None = None

    # ---- events from the adapter's VehicleState (the Events protocol) ---------------------
    def on_measurement(self, m: Measurement) -> None:
        t = self._t
        m = dataclasses.replace(m, capture_t_s=t, receipt_t_s=t)
        self.counters.measurements += 1
        if self.tracker is None:
            self._start(m)
        self._pending.append(m)
        if m.sys_id is not None:
            for (sys_id, _), v in self.vehicles.items():
                if sys_id == m.sys_id:
                    pos = (m.lat_deg, m.lon_deg, m.alt_amsl_m)
                    v.positions += 1
                    if v.first_position is None:
                        v.first_position = pos
                    v.last_position = pos
                    break

    def on_status(self, s: VehicleStatus) -> None:
        self.statuses[int(s.sys_id)] = s

    def on_hazard(self, h: HazardReport) -> None:
        self.hazards.append(h)

    def on_vehicle(self, v: VehicleInfo) -> None:
        self.infos[(int(v.key.sys_id), v.key.comp_id)] = v

    def on_link_health(self, h: LinkHealth) -> None:
        pass  # link health is a live-link concern; a tlog has no receive path to judge

    # ---- input -----------------------------------------------------------------------------
    def feed_packet(self, t_s: float, packet: bytes) -> None:
        """One tlog record: run the monitoring cycles due before ``t_s``, then decode."""
        self.records += 1
        if self.first_t_s is None:
            self.first_t_s = t_s
        self.last_t_s = t_s
        self._run_due_cycles(t_s)
        self._t = t_s
        for m in self.parser.feed(packet, datagram=True):
            try:
                self._dispatch(m, t_s)
            except Exception:  # a handler bug must not end the replay; it is counted
                self.counters.handler_errors += 1
                _log.exception("handler failed on %s", m.get_type())

    def finish(self) -> None:
        """Ingest what is pending and run a last cycle at the last record time."""
        if self.last_t_s is not None and self.tracker is not None and self._pending:
            self._cycle(self.last_t_s)

    def _dispatch(self, m: wire.MavMsg, t_s: float) -> None:
        sys_id, comp_id, seq = wire.src(m)
        mid = wire.msg_id(m)
        if mid == wire.HEARTBEAT and int(m.autopilot) == MAV_AUTOPILOT_INVALID:
            self.counters.gcs_messages += 1
            return
        key = (sys_id, comp_id)
        st = self._states.get(key)
        if st is None:
            vkey = VehicleKey(link=self.link, address="", sys_id=SysId(sys_id), comp_id=comp_id)
            st = self._states[key] = VehicleState(vkey, self.mavlink, t_s)
            self.vehicles[key] = _VehicleStats(sys_id=sys_id, comp_id=comp_id, first_t_s=t_s)
        v = self.vehicles[key]
        v.messages += 1
        v.last_t_s = t_s
        st.count_frame(seq, t_s)
        if mid == wire.ADSB_VEHICLE:
            self.adsb_relay.on_adsb_vehicle(st, m, t_s, self)
            return
        handler = _HANDLERS.get(mid)
        if handler is not None:
            handler(st, m, t_s, self)

    # ---- tracking and monitoring -------------------------------------------------------------
    def _start(self, m: Measurement) -> None:
        if self.frame is None:
            self.frame = LocalFrame(m.lat_deg, m.lon_deg, ground_elevation_amsl_m=m.alt_amsl_m)
        self.tracker = Tracker(self.frame, self.tracking)
        self.tracker.set_operations(self.operations.values())
        self.monitor = Monitor(self.frame, self.monitoring)
        self._next_cycle_t_s = m.capture_t_s + self.period_s
        _log.info("frame origin %.6f, %.6f (EPSG %d)", m.lat_deg, m.lon_deg, self.frame.epsg)

    def _run_due_cycles(self, t_s: float) -> None:
        nxt = self._next_cycle_t_s
        if nxt is None or t_s < nxt:
            return
        missed = math.floor((t_s - nxt) / self.period_s)
        if missed > _MAX_CATCH_UP_CYCLES:
            self._cycle(nxt)
            skip = missed - 1
            self.counters.skipped_cycles += skip
            nxt += (skip + 1) * self.period_s
        while nxt <= t_s:
            self._cycle(nxt)
            nxt += self.period_s
        self._next_cycle_t_s = nxt

    def _cycle(self, t_s: float) -> None:
        tracker, monitor = self.tracker, self.monitor
        assert tracker is not None and monitor is not None
        self.counters.cycles += 1
        if self._pending:
            tracker.ingest(self._pending)
            self._pending = []
        tracker.check_stale(t_s)
        self._update_tracks(tracker)
        tracks, prediction = tracker.snapshot(t_s)
        snap = AirspaceSnapshot(
            t_s=t_s,
            operations=dict(self.operations),
            tracks=tracks,
            geofences=self.geofences,
            prediction=prediction,
        )
        for threat in monitor.cycle(snap):
            self._record_threat(threat, t_s)

    def _update_tracks(self, tracker: Tracker) -> None:
        for tid, tr in tracker.tracks().items():
            pos = (tr.east_m, tr.north_m, tr.alt_amsl_m)
            ts = self.tracks.get(tid)
            if ts is None:
                self.tracks[tid] = _TrackStats(
                    first_t_s=tr.t_s,
                    last_t_s=tr.t_s,
                    raw_updates=tr.updates,
                    last=pos,
                    last_wgs84=(tr.lat_deg, tr.lon_deg, tr.alt_amsl_m),
                    cooperative=tr.cooperative,
                )
                continue
            if tr.t_s <= ts.last_t_s:
                continue
            step = math.dist(ts.last, pos)
            ts.distance_m += step
            ts.max_speed_mps = max(ts.max_speed_mps, tr.ground_speed_mps)
            ts.last_t_s = tr.t_s
            ts.last = pos
            ts.last_wgs84 = (tr.lat_deg, tr.lon_deg, tr.alt_amsl_m)
            if tr.updates < ts.raw_updates:  # a dropped and re-created intruder: add up
                ts.base_updates += ts.raw_updates
            ts.raw_updates = tr.updates

    def _record_threat(self, th: Threat, t_s: float) -> None:
        rec = self.threats.get(th.id)
        if rec is None:
            rec = self.threats[th.id] = _ThreatStats(
                kind=th.kind.value,
                uas=tuple(str(u) for u in th.uas_ids),
                intruder=th.intruder_id,
                first_t_s=th.detected_at_s,
                last_t_s=t_s,
                message=th.message,
            )
        else:
            rec.cycles += 1
            rec.last_t_s = t_s
        if th.status.value == "closed":
            rec.closed_t_s = t_s
        if th.closest_approach_m is not None:
            cur = rec.min_closest_approach_m
            rec.min_closest_approach_m = (
                th.closest_approach_m if cur is None else min(cur, th.closest_approach_m)
            )
        if th.predicted_event_at_s is not None and rec.predicted_event_t_s is None:
            rec.predicted_event_t_s = th.predicted_event_at_s

    # ---- report ------------------------------------------------------------------------------
    def report(self, *, path: Path, counters: TlogCounters, wall_s: float) -> dict[str, Any]:
        """The JSON-able report. Times are POSIX seconds; ``*_rel_s`` are seconds after the
        first record."""
        t0 = self.first_t_s or 0.0

        def rel(t: float | None) -> float | None:
            return None if t is None else round(t - t0, 3)

        vehicles = []
        for key in sorted(self.vehicles):
            v = self.vehicles[key]
            info = self.infos.get(key)
            if info is None and v.positions == 0:
                continue  # not a vehicle: no autopilot heartbeat, no position
            status = self.statuses.get(v.sys_id)
            vehicles.append(
                {
                    "sys_id": v.sys_id,
                    "comp_id": v.comp_id,
                    "autopilot": info.autopilot.value if info else "unknown",
                    "vehicle_kind": (
                        info.vehicle_kind.value if info and info.vehicle_kind else None
                    ),
                    "mav_type": info.mav_type if info else None,
                    "messages": v.messages,
                    "positions": v.positions,
                    "first_t_s": v.first_t_s,
                    "last_t_s": v.last_t_s,
                    "first_position": _pos_json(v.first_position),
                    "last_position": _pos_json(v.last_position),
                    "last_mode": status.mode.value if status else None,
                    "armed": status.armed if status else None,
                }
            )
        tracks = {
            tid: {
                "cooperative": ts.cooperative,
                "updates": ts.updates,
                "first_t_s": ts.first_t_s,
                "last_t_s": ts.last_t_s,
                "first_rel_s": rel(ts.first_t_s),
                "last_rel_s": rel(ts.last_t_s),
                "last_position": _pos_json(ts.last_wgs84),
                "distance_m": round(ts.distance_m, 2),
                "max_ground_speed_mps": round(ts.max_speed_mps, 2),
            }
            for tid, ts in sorted(self.tracks.items())
        }
        threats = [
            {
                "id": tid,
                "kind": th.kind,
                "uas": list(th.uas),
                "intruder": th.intruder,
                "first_t_s": th.first_t_s,
                "last_t_s": th.last_t_s,
                "first_rel_s": rel(th.first_t_s),
                "last_rel_s": rel(th.last_t_s),
                "closed_t_s": th.closed_t_s,
                "cycles": th.cycles,
                "min_closest_approach_m": th.min_closest_approach_m,
                "predicted_event_t_s": th.predicted_event_t_s,
                "message": th.message,
            }
            for tid, th in sorted(self.threats.items(), key=lambda kv: kv[1].first_t_s)
        ]
        hazards = [
            {
                "kind": h.kind.value,
                "sys_id": h.sys_id,
                "t_s": h.t_s,
                "rel_s": rel(h.t_s),
                "message": h.message,
            }
            for h in self.hazards
        ]
        tc = self.tracker.counters if self.tracker is not None else {}
        reasons = ("out_of_order", "duplicate", "invalid", "gate", "unassociated")
        pc = self.parser.counters
        return {
            "file": str(path),
            "records": self.records,
            "vehicles": vehicles,
            "duration": {
                "first_t_s": self.first_t_s,
                "last_t_s": self.last_t_s,
                "duration_s": (
                    round(self.last_t_s - self.first_t_s, 3)
                    if self.first_t_s is not None and self.last_t_s is not None
                    else 0.0
                ),
            },
            "frame": (
                None
                if self.frame is None
                else {
                    "origin_lat_deg": self.frame.origin_lat_deg,
                    "origin_lon_deg": self.frame.origin_lon_deg,
                    "ground_elevation_amsl_m": self.frame.ground_elevation_amsl_m,
                    "epsg": self.frame.epsg,
                }
            ),
            "tracks": tracks,
            "threats": threats,
            "hazards": hazards,
            "counters": {
                "corrupt_records": counters.corrupt_chunks + counters.truncated_tail,
                "tlog": counters.as_dict(),
                "adsb_relay": dataclasses.asdict(self.adsb_relay.counters),
                "bad_frames": {
                    "bad_crc": pc.bad_crc,
                    "garbage": pc.garbage,
                    "truncated": pc.truncated,
                    "bad_signature": pc.bad_signature,
                },
                "frames": pc.frames,
                # valid frames of messages outside the adapter's common dialect (ArduPilot-
                # or PX4-specific): the tlog reader checked their CRC; telemetry ignores them
                "frames_not_in_common_dialect": pc.unknown_msg,
                "gcs_messages": self.counters.gcs_messages,
                "handler_errors": self.counters.handler_errors,
                "measurements": self.counters.measurements,
                "accepted_measurements": tc.get("accepted", 0),
                "rejected_measurements": {r: tc.get(r, 0) for r in reasons},
                "monitoring_cycles": self.counters.cycles,
                "skipped_cycles": self.counters.skipped_cycles,
            },
            "wall_s": round(wall_s, 3),
        }


def _pos_json(p: tuple[float, float, float] | None) -> dict[str, float] | None:
    if p is None:
        return None
    return {"lat_deg": p[0], "lon_deg": p[1], "alt_amsl_m": p[2]}


# ---- running it ------------------------------------------------------------------------------


async def replay_file(
    path: Path,
    *,
    speed: float | None = None,
    pipeline: ReplayPipeline | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Replay ``path`` through ``pipeline`` (a new one by default) and return the report.
    ``on_progress(bytes_done)`` is called every few hundred records. Raises
    :class:`ReplayError` for a missing file or one without a single valid record."""
    if not path.is_file():
        raise ReplayError(path, _not_a_file(path))
    pipe = pipeline or ReplayPipeline(link=f"tlog:{path.name}")
    done = 0

    def on_packet(t_s: float, packet: bytes) -> None:
        nonlocal done
        pipe.feed_packet(t_s, packet)
        done += 8 + len(packet)
        if on_progress is not None and pipe.records % _PROGRESS_EVERY == 0:
            on_progress(done)

    try:
        stats: ReplayStats = await replay(path, on_packet, speed=speed)
    except OSError as exc:
        raise ReplayError(path, f"cannot read: {exc.strerror or exc}") from exc
    pipe.finish()
    if stats.records == 0:
        c = stats.counters
        raise ReplayError(
            path,
            f"no valid tlog record ({c.skipped_bytes} bytes skipped, "
            f"{c.corrupt_chunks} corrupt chunks): not a .tlog file?",
        )
    return pipe.report(path=path, counters=stats.counters, wall_s=stats.wall_s)


def first_record_t_s(path: Path) -> float | None:
    """Time of the first valid record of ``path`` (None when it has none)."""
    for rec in TlogReader(path):
        return rec.t_s
    return None


def scenario_pipeline(path: Path, scenario_path: Path) -> ReplayPipeline:
    """A pipeline with the operations and geofences of ``scenario_path``, its t0 set to the
    first record time of ``path``."""
    from gcs_utm.scenario import load_any

    t0 = first_record_t_s(path)
    if t0 is None:
        raise ReplayError(path, "no valid tlog record: not a .tlog file?")
    scenario = load_any(scenario_path, t0_s=t0)
    return ReplayPipeline(
        link=f"tlog:{path.name}",
        frame=scenario.frame,
        operations=scenario.operations,
        geofences=scenario.geofences,
    )


def _not_a_file(path: Path) -> str:
    return "is a directory, not a .tlog file" if path.is_dir() else "no such file"


def parse_speed(text: str) -> float | None:
    """``max`` (as fast as possible) or a positive factor (1 = real time). ``0`` is refused,
    not read as ``max``: a factor of 0 would mean a stopped clock."""
    if text.strip().lower() in ("max", "inf"):
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a positive number or 'max', got {text!r}"
        ) from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a positive number or 'max', got {text!r}")
    return value


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a .tlog through tracking and monitoring and write a JSON report",
        description="Replay a .tlog into the telemetry -> tracking -> monitoring pipeline, "
        "using record times as capture times. Corrupt records are skipped and counted.",
    )
    p.add_argument("tlog", type=Path, help="the .tlog file")
    p.add_argument(
        "--speed",
        type=parse_speed,
        default=None,
        metavar="N|max",
        help="1 = real time, N = N times faster, max = as fast as possible (default)",
    )
    p.add_argument(
        "--report",
        type=Path,
        default=None,
        help="JSON report path (default: ./<name>.replay.json)",
    )
    p.add_argument(
        "--scenario",
        type=Path,
        default=None,
        help="scenario file whose operations/geofences apply (its t0 = the first record time)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        DownloadColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    path: Path = args.tlog
    out: Path = args.report or Path(f"{path.stem}.replay.json")
    if not path.is_file():
        print(f"gcs-utm replay: {path}: {_not_a_file(path)}", file=sys.stderr)
        return 2
    pipeline = None
    if args.scenario is not None:
        try:
            pipeline = scenario_pipeline(path, args.scenario)
        except (ReplayError, ScenarioError, OSError) as exc:
            print(f"gcs-utm replay: {exc}", file=sys.stderr)
            return 1
    total = path.stat().st_size
    progress = Progress(
        TextColumn("replay {task.description}"),
        BarColumn(),
        DownloadColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        disable=bool(args.no_progress),
    )
    with progress:
        task = progress.add_task(path.name, total=total)
        try:
            report = asyncio.run(
                replay_file(
                    path,
                    speed=args.speed,
                    pipeline=pipeline,
                    on_progress=lambda done: progress.update(task, completed=done),
                )
            )
        except ReplayError as exc:
            progress.stop()
            print(f"gcs-utm replay: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            progress.stop()
            print("gcs-utm replay: interrupted", file=sys.stderr)
            return 130
        progress.update(task, completed=total)
    try:
        out.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    except OSError as exc:
        print(f"gcs-utm replay: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    c = report["counters"]
    print(
        f"{report['records']} records, {report['duration']['duration_s']:.1f} s, "
        f"{len(report['vehicles'])} vehicles, {len(report['tracks'])} tracks, "
        f"{len(report['threats'])} threats, {c['corrupt_records']} corrupt records, "
        f"{sum(c['rejected_measurements'].values())} rejected measurements -> {out}"
    )
    return 0
