"""The replay pipeline of ``gcs-utm replay``: recorded MAVLink and ADS-B run through the same
decoders as a live link (MAVLink telemetry decoder -> Tracking -> Monitoring), ending in a
JSON-able report. Inputs and pacing: :mod:`gcs_utm.cli.replay_inputs`; the command:
:mod:`gcs_utm.cli.replay`.

Pipeline (:class:`ReplayPipeline`, sans-IO: feed it ``(record t_s, packet)`` and
``(receipt t_s, ADS-B measurement)`` in time order):

- every record's packet is parsed by the MAVLink adapter's parser
  (:class:`adapters.mavlink.wire.Parser`) and dispatched, per (sysid, compid), to the adapter's
  per-vehicle telemetry state (:class:`adapters.mavlink.vehicle.VehicleState`) through the
  hub's own handler table (:func:`adapters.mavlink.handlers.message_handlers`), exactly as on a
  live link (HOME_POSITION gives each vehicle's home, reported with the height above it);
  ground stations (HEARTBEAT autopilot ``MAV_AUTOPILOT_INVALID``) are
  not vehicles;
- the **record time is the capture time** (and the receipt time) of every measurement: the
  vehicle-clock mapping of a live link is replaced, because a tlog's record times are the only
  clock all vehicles in it share;
- ADS-B measurements decoded from receiver captures (:meth:`ReplayPipeline.feed_measurement`)
  keep the capture time their decoder gave them (the SBS-1 "generated" time, else receipt),
  as on a live feed; they are intruder tracks ``icao:<hex>`` unless an operation declares the
  address;
- the airspace frame's origin is the first position seen (its altitude is the frame's ground
  elevation; 0 m when that first position is an ADS-B aircraft); tracks are built by
  :class:`gcs_utm.core.tracking.Tracker`. Without operations
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

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adapters.mavlink import wire
from adapters.mavlink.adsb_relay import AdsbRelay
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.handlers import message_handlers
from adapters.mavlink.vehicle import VehicleInfo, VehicleState
from adapters.remoteid.config import RemoteIdConfig
from adapters.remoteid.ingest import RidIngest
from adapters.remoteid.tracks import RidTracks
from adapters.remoteid.vehicles import RidVehicles
from adapters.tlog import TlogCounters
from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.messages import HazardReport, LinkHealth, VehicleKey, VehicleStatus
from gcs_utm.model import (
    AirspaceSnapshot,
    Geofence,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    Position,
    SysId,
    Threat,
    TrackId,
)

_log = logging.getLogger(__name__)

MAV_AUTOPILOT_INVALID = 8  # a ground station or companion, not a vehicle
_MAX_CATCH_UP_CYCLES = 30  # beyond this many silent periods, jump to the next record


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
    adsb_capture_measurements: int = 0
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
        remote_id: RemoteIdConfig | None = None,
    ) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s must be positive, got {period_s}")
        self.link = link
        self.mavlink = mavlink or MavlinkConfig()
        self.tracking = tracking or TrackingConfig()
        self.monitoring = monitoring or MonitoringConfig()
        self.remote_id_config = remote_id or RemoteIdConfig()
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
        # OPEN_DRONE_ID_* and ODID texts as on a live link (docs/remote-id.md): identities,
        # RID positions, REMOTE_ID_MISMATCH hazards (compared with the replayed telemetry)
        self.remote_id = RidVehicles()
        self.rid_ingest = RidIngest(
            consistency_m=self.remote_id_config.consistency_m,
            position_of=self._telemetry_position,
        )
        self.rid_ingest.register(self.remote_id)
        self._handlers = message_handlers(self.adsb_relay, self.remote_id)  # the live hub's
        self._pending: list[Measurement] = []
        self._t = 0.0
        self._next_cycle_t_s: float | None = None

    # ---- events from the adapter's VehicleState (the Events protocol) ---------------------
    def on_measurement(self, m: Measurement) -> None:
        t = self._t
        self._accept(dataclasses.replace(m, capture_t_s=t, receipt_t_s=t))

    def _accept(self, m: Measurement) -> None:
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

    def _telemetry_position(self, sys_id: int) -> tuple[Position, float] | None:
        """A vehicle's last telemetry position and when it was last heard (RidIngest's
        ``position_of``, as the live hub's :func:`telemetry_positions`)."""
        for (sid, _), st in self._states.items():
            if sid == sys_id and st.last_position is not None:
                return st.last_position, st.last_heard_t_s
        return None

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

    def feed_measurement(self, t_s: float, m: Measurement) -> None:
        """One ADS-B measurement decoded from a receiver capture, received at ``t_s``: run
        the monitoring cycles due before ``t_s``, then hand it to tracking as it is."""
        if self.first_t_s is None:
            self.first_t_s = t_s
        self.last_t_s = t_s
        self._run_due_cycles(t_s)
        self._t = t_s
        self.counters.adsb_capture_measurements += 1
        self._accept(m)

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
        handler = self._handlers.get(mid)
        if handler is not None:
            handler(st, m, t_s, self)

    # ---- tracking and monitoring -------------------------------------------------------------
    def _start(self, m: Measurement) -> None:
        if self.frame is None:
            # an aircraft's altitude is no ground elevation: 0 m then
            ground_m = 0.0 if m.source is MeasurementSource.ADSB else m.alt_amsl_m
            self.frame = LocalFrame(m.lat_deg, m.lon_deg, ground_elevation_amsl_m=ground_m)
        self.tracker = Tracker(self.frame, self.tracking)
        self.tracker.set_operations(self.operations.values())
        self.monitor = Monitor(self.frame, self.monitoring)
        self._next_cycle_t_s = self._t + self.period_s
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
    def report(
        self,
        *,
        path: Path,
        counters: TlogCounters,
        wall_s: float,
        inputs: Sequence[dict[str, Any]] = (),
        adsb_feeds: dict[str, dict[str, int]] | None = None,
    ) -> dict[str, Any]:
        """The JSON-able report. Times are POSIX seconds; ``*_rel_s`` are seconds after the
        first record. ``inputs`` lists the files replayed, ``adsb_feeds`` the counts of each
        receiver capture (``counters.adsb_feeds``)."""
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
                    "home": _pos_json(_home(status)),
                    "last_height_above_home_m": _above_home(status, v.last_position),
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
            "inputs": list(inputs) or [{"path": str(path), "kind": "tlog"}],
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
            "remote_id": self._remote_id_report(),
            "counters": {
                "corrupt_records": counters.corrupt_chunks + counters.truncated_tail,
                "tlog": counters.as_dict(),
                "adsb_relay": dataclasses.asdict(self.adsb_relay.counters),
                "adsb_feeds": adsb_feeds or {},
                "adsb_capture_measurements": self.counters.adsb_capture_measurements,
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

    def _remote_id_report(self) -> dict[str, Any]:
        """The Remote ID heard: each source's identity on its track, and the counters."""
        on_tracks = RidTracks(lambda: self.rid_ingest.aircraft, self.operations.values)
        return {
            "declared_sys_ids": sorted(self.remote_id.declared),
            "identities": [
                {"track_id": tid, **dataclasses.asdict(ident)}
                for tid, ident in sorted(on_tracks.by_track().items())
            ],
            "counters": {
                **dataclasses.asdict(self.remote_id.counters),
                **dataclasses.asdict(self.rid_ingest.counters),
            },
        }


def _pos_json(p: tuple[float, float, float] | None) -> dict[str, float] | None:
    if p is None:
        return None
    return {"lat_deg": p[0], "lon_deg": p[1], "alt_amsl_m": p[2]}


def _home(status: VehicleStatus | None) -> tuple[float, float, float] | None:
    home = None if status is None else status.home
    return None if home is None else (home.lat_deg, home.lon_deg, home.alt_amsl_m)


def _above_home(
    status: VehicleStatus | None, last: tuple[float, float, float] | None
) -> float | None:
    """The last position's height above the vehicle's home (AGL where home is on the
    ground), as the live service reads relative altitudes; None without a home."""
    home = _home(status)
    if home is None or last is None:
        return None
    return round(last[2] - home[2], 3)
