"""What a replay saw, for its report: the telemetry sink of the replay's MAVLink hub (it counts,
then hands every measurement on to tracking), the threats Monitoring raised, and the tracks as
each monitoring cycle found them (:class:`ReplayLog`). The report built from it and the
runtime's parts is :mod:`gcs_utm.app.replay_report`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from adapters.mavlink.vehicle import VehicleInfo
from gcs_utm.core.tracking import Tracker
from gcs_utm.messages import HazardReport, LinkHealth, VehicleStatus
from gcs_utm.model import Measurement, Threat, TrackId

Point = tuple[float, float, float]  # lat_deg, lon_deg, alt_amsl_m (or east_m, north_m, alt)


@dataclass(slots=True)
class _Positions:
    count: int = 0
    first: Point | None = None
    last: Point | None = None


@dataclass(slots=True)
class _TrackStats:
    first_t_s: float
    last_t_s: float
    raw_updates: int
    last: Point  # east_m, north_m, alt_amsl_m
    last_wgs84: Point
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
class ReplayLog:
    """The replay's :class:`~adapters.mavlink.hub.TelemetrySink` and Monitoring's threat sink.
    ``submit`` (tracking's input) and ``now_s`` (the replay clock) are set by the builder."""

    submit: Callable[[Measurement], None] = lambda _m: None
    now_s: Callable[[], float] = lambda: 0.0
    measurements: int = 0
    capture_measurements: int = 0
    positions: dict[int, _Positions] = field(default_factory=dict)  # by system id
    infos: dict[tuple[int, int], VehicleInfo] = field(default_factory=dict)
    statuses: dict[int, VehicleStatus] = field(default_factory=dict)
    hazards: list[HazardReport] = field(default_factory=list)
    tracks: dict[TrackId, _TrackStats] = field(default_factory=dict)
    threats: dict[str, _ThreatStats] = field(default_factory=dict)

    # ---- the hub's telemetry sink -----------------------------------------------------------
    def on_measurement(self, m: Measurement) -> None:
        self.measurements += 1
        if m.sys_id is not None:
            p = self.positions.setdefault(int(m.sys_id), _Positions())
            p.count += 1
            p.last = (m.lat_deg, m.lon_deg, m.alt_amsl_m)
            if p.first is None:
                p.first = p.last
        self.submit(m)

    def on_capture(self, m: Measurement) -> None:
        """An ADS-B measurement decoded from a receiver capture (the live feed's decoder)."""
        self.capture_measurements += 1
        self.on_measurement(m)

    def on_status(self, s: VehicleStatus) -> None:
        self.statuses[int(s.sys_id)] = s

    def on_hazard(self, h: HazardReport) -> None:
        self.hazards.append(h)

    async def on_tracking_hazard(self, h: HazardReport) -> None:
        self.hazards.append(h)

    def on_vehicle(self, v: VehicleInfo) -> None:
        self.infos[(int(v.key.sys_id), v.key.comp_id)] = v

    def on_link_health(self, h: LinkHealth) -> None:
        pass  # a recording has no receive path of its own to judge

    # ---- monitoring -------------------------------------------------------------------------
    def on_cycle(self, tracker: Tracker) -> None:
        """A monitoring cycle is about to run: the tracks as they are (distance, speed)."""
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
            ts.distance_m += math.dist(ts.last, pos)
            ts.max_speed_mps = max(ts.max_speed_mps, tr.ground_speed_mps)
            ts.last_t_s = tr.t_s
            ts.last = pos
            ts.last_wgs84 = (tr.lat_deg, tr.lon_deg, tr.alt_amsl_m)
            if tr.updates < ts.raw_updates:  # a dropped and re-created intruder: add up
                ts.base_updates += ts.raw_updates
            ts.raw_updates = tr.updates

    async def on_threats(self, threats: list[Threat]) -> None:
        t_s = self.now_s()
        for th in threats:
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
