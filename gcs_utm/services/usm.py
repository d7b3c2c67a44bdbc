"""U-space Service Manager (paper §4.1): the only door between the UTM core and the world.

In: measurements, vehicle status, hazards and new vehicles from the MAVLink hub (and ADS-B,
tlog, MQTT through the same methods); threats from Monitoring; decisions from Emergency
Management; pilot answers from the dashboard or MQTT.
Out: recommendations to the operator(s); accepted plans uploaded to the vehicle as a MAVLink
mission (verified by readback) and then installed as a new plan version; commands; new
geofences into the airspace; everything recorded.

The recommendation and answer lifecycle (proposals, answers, uploads, final states) lives in
:mod:`gcs_utm.services.recommendations`, a base class of :class:`Usm`; its invariants are
stated there. Nothing is dropped silently: every outcome goes to the record callback and the
event log.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from gcs_utm.clock import Clock
from gcs_utm.config import setting
from gcs_utm.messages import (
    FlightMode,
    HazardReport,
    LinkHealth,
    VehicleStatus,
)
from gcs_utm.model import (
    LANE_STRIDE,
    AuditEntry,
    Autopilot,
    Command,
    CommandKind,
    FlightPlan,
    Geofence,
    LaneSource,
    Measurement,
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
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services.airspace import Airspace, AirspaceError
from gcs_utm.services.recommendations import (
    AnswerOutcome,
    AnswerStatus,
    CommandOutcome,
    OperatorPort,
    RecommendationLifecycle,
    RecommendationRecord,
    UploadOutcome,
    VehiclePort,
    resume_index,
)

__all__ = [
    "AnswerOutcome",
    "AnswerStatus",
    "CommandOutcome",
    "OperatorPort",
    "RecommendationRecord",
    "UploadOutcome",
    "Usm",
    "UsmConfig",
    "VehiclePort",
    "resume_index",
]

_log = logging.getLogger(__name__)

_LANE_FOLD_ENTRIES = 512
"""Lane entries kept before they are added to their sources' statistics (in one pass with
NumPy, ~0.3 ms; reading :attr:`Usm.telemetry` adds them at once)."""
_LANE_RECEIPT = 1  # fields of a PositionLane entry (gcs_utm.model.LANE_STRIDE)
_LANE_CAPTURE = 2
_LANE_ALT = 5


_NAV_WAYPOINT = 16
_NAV_LOITER_TIME = 19
_NAV_LAND = 21
_NAV_TAKEOFF = 22
_DO_CHANGE_SPEED = 178
_RELATIVE_FRAMES = frozenset({3, 6})  # MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT): metres above home


def mission_to_plan(
    items: Sequence[object],
    op_id: OperationId,
    *,
    t0_s: float,
    cruise_speed_mps: float,
    home_alt_amsl_m: float | None,
    skip_first: bool = False,
) -> FlightPlan | None:
    """A 4D plan from a downloaded MAVLink mission: its positional items in order, times from
    the DO_CHANGE_SPEED items (else ``cruise_speed_mps``) starting at ``t0_s``. Relative
    altitudes are made AMSL with ``home_alt_amsl_m`` (the vehicle's first reported altitude:
    it connects on the ground); without it such items are skipped."""
    import math

    speed = cruise_speed_mps
    wps: list[Waypoint4D] = []
    for i, it in enumerate(items):
        if skip_first and i == 0:
            continue  # ArduPilot: seq 0 is home
        command = int(getattr(it, "command", -1))
        if command == _DO_CHANGE_SPEED:
            value = float(getattr(it, "param2", 0.0))
            if value > 0.0:
                speed = value
            continue
        if command not in (_NAV_WAYPOINT, _NAV_LOITER_TIME, _NAV_LAND, _NAV_TAKEOFF):
            continue
        lat = float(getattr(it, "x", 0)) / 1e7
        lon = float(getattr(it, "y", 0)) / 1e7
        alt = float(getattr(it, "z", 0.0))
        if int(getattr(it, "frame", 0)) in _RELATIVE_FRAMES:
            if home_alt_amsl_m is None:
                continue
            alt += home_alt_amsl_m
        if (lat, lon) == (0.0, 0.0) and wps:  # takeoff/land "here": same place as before
            lat, lon = wps[-1].lat_deg, wps[-1].lon_deg
        if (lat, lon) == (0.0, 0.0):
            continue
        t = t0_s
        if wps:
            prev = wps[-1]
            k = math.cos(math.radians(prev.lat_deg))
            dist = math.hypot(
                (lat - prev.lat_deg) * 110_540.0,
                (lon - prev.lon_deg) * 111_320.0 * k,
                alt - prev.alt_amsl_m,
            )
            t = prev.t_s + dist / max(speed, 0.1)
        try:
            wps.append(Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=alt, t_s=t))
        except ValueError:
            continue  # a malformed item is skipped, not fatal
    if not wps:
        return None
    return FlightPlan(
        operation_id=op_id,
        version=1,
        waypoints=tuple(wps),
        created_t_s=t0_s,
        reason="downloaded from the vehicle",
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class UsmConfig:
    """USM behaviour (section ``[usm]``)."""

    hazard_cooldown_s: float = setting(
        30.0,
        "a hazard of the same kind for the same UAS within this time is coalesced, not re-raised",
        min=0.0,
        unit="s",
    )
    event_log_size: int = setting(500, "events kept for the dashboard", min=10)
    upload_attempts: int = setting(
        2,
        "whole-mission upload attempts (each with the link's own per-item retries) before a "
        "recommendation is marked failed",
        min=1,
        max=10,
    )
    default_priority: int = setting(1, "priority of an operation created from a vehicle")
    default_flight_geometry_m: float = setting(
        10.0, "flight-geometry radius of an operation created from a vehicle", min=0.1, unit="m"
    )
    default_operational_volume_m: float = setting(
        30.0,
        "operational-volume radius of an operation created from a vehicle",
        min=0.1,
        unit="m",
    )
    default_cruise_speed_mps: float = setting(
        5.0,
        "cruise speed assumed for a vehicle's downloaded mission without speed items",
        min=0.1,
        unit="m/s",
    )


@dataclass(slots=True)
class TelemetryStats:
    """Per-source counts and delays (receipt minus capture, in clock seconds).

    Delays are not clamped at zero: a negative minimum means the vehicle clock runs ahead of
    ours (a clock mapping error), which a clamp would hide."""

    count: int = 0
    first_capture_t_s: float = 0.0
    last_capture_t_s: float = 0.0
    delay_sum_s: float = 0.0
    delay_min_s: float = math.inf
    delay_max_s: float = -math.inf

    def add(self, m: Measurement) -> None:
        t = m.capture_t_s
        if self.count == 0:
            self.first_capture_t_s = t
        self.count += 1
        self.last_capture_t_s = max(self.last_capture_t_s, t)
        delay = m.receipt_t_s - t
        self.delay_sum_s += delay
        self.delay_min_s = min(self.delay_min_s, delay)
        self.delay_max_s = max(self.delay_max_s, delay)

    def combined(self, other: TelemetryStats) -> TelemetryStats:
        """Both sets of reports in one (a source that reached us both ways)."""
        if not other.count:
            return self
        if not self.count:
            return other
        return TelemetryStats(
            count=self.count + other.count,
            first_capture_t_s=min(self.first_capture_t_s, other.first_capture_t_s),
            last_capture_t_s=max(self.last_capture_t_s, other.last_capture_t_s),
            delay_sum_s=self.delay_sum_s + other.delay_sum_s,
            delay_min_s=min(self.delay_min_s, other.delay_min_s),
            delay_max_s=max(self.delay_max_s, other.delay_max_s),
        )

    def as_dict(self, speed: float) -> dict[str, float | int]:
        span = self.last_capture_t_s - self.first_capture_t_s
        # delays are measured on the (possibly sped-up) clock: divide by the speed to get
        # wall-clock seconds, which is what a link's latency really is
        scale = 1.0 / speed if speed not in (0.0, float("inf")) else 1.0
        return {
            "messages": self.count,
            "rate_hz": round((self.count - 1) / span, 3) if span > 0 else 0.0,
            "mean_delay_ms": round(1000.0 * scale * self.delay_sum_s / self.count, 3)
            if self.count
            else 0.0,
            "min_delay_ms": round(1000.0 * scale * self.delay_min_s, 3) if self.count else 0.0,
            "max_delay_ms": round(1000.0 * scale * self.delay_max_s, 3) if self.count else 0.0,
        }


class _LaneStats:
    """:class:`TelemetryStats` of every lane source, as arrays indexed by source index.

    Lane entries are added in bursts of at least ``_LANE_FOLD_ENTRIES`` (and whenever
    read), with NumPy: ``ufunc.at`` applies repeated indices one after another in order, so
    every number is the one :meth:`TelemetryStats.add` gives report by report."""

    def __init__(self) -> None:
        self.keys: list[str] = []
        self._count = np.zeros(0, dtype=np.int64)
        self._first = np.zeros(0)
        self._last = np.zeros(0)
        self._sum = np.zeros(0)
        self._min = np.zeros(0)
        self._max = np.zeros(0)
        self._backlog: list[float] = []

    @property
    def size(self) -> int:
        return len(self.keys)

    def append(self, key: str) -> None:
        """One more source (index ``size``), with the statistics key ``key``."""
        self.keys.append(key)
        if len(self.keys) > len(self._count):
            cap = max(64, 2 * len(self._count))

            def grown(a: npt.NDArray[Any], fill: float) -> npt.NDArray[Any]:
                out = np.full(cap, fill, dtype=a.dtype)
                out[: len(a)] = a
                return out

            self._count = grown(self._count, 0)
            self._first = grown(self._first, 0.0)
            self._last = grown(self._last, 0.0)
            self._sum = grown(self._sum, 0.0)
            self._min = grown(self._min, math.inf)
            self._max = grown(self._max, -math.inf)

    def add(self, values: list[float]) -> None:
        self._backlog += values
        if len(self._backlog) >= _LANE_FOLD_ENTRIES * LANE_STRIDE:
            self.fold()

    def fold(self) -> None:
        if not self._backlog:
            return
        a = np.array(self._backlog, dtype=np.float64).reshape(-1, LANE_STRIDE)
        self._backlog = []
        idx = a[:, 0].astype(np.intp)
        cap = a[:, _LANE_CAPTURE]
        delay = a[:, _LANE_RECEIPT] - cap
        used, first_at = np.unique(idx, return_index=True)
        new = self._count[used] == 0
        self._first[used[new]] = cap[first_at[new]]
        np.add.at(self._count, idx, 1)
        np.maximum.at(self._last, idx, cap)
        np.add.at(self._sum, idx, delay)
        np.minimum.at(self._min, idx, delay)
        np.maximum.at(self._max, idx, delay)

    def items(self) -> list[tuple[str, TelemetryStats]]:
        """(key, statistics) per source heard so far (call :meth:`fold` first)."""
        n = self.size
        rows = zip(
            self.keys,
            self._count[:n].tolist(),
            self._first[:n].tolist(),
            self._last[:n].tolist(),
            self._sum[:n].tolist(),
            self._min[:n].tolist(),
            self._max[:n].tolist(),
            strict=True,
        )
        return [
            (key, TelemetryStats(count, first, last, total, low, high))
            for key, count, first, last, total, low, high in rows
            if count
        ]


_T = TypeVar("_T")


def _latest_per_sys_id(
    per_vehicle: dict[tuple[SysId, str], _T], when: Callable[[_T], float]
) -> dict[SysId, _T]:
    """Of the entries kept per (system id, vehicle), the one with the latest ``when`` for each
    system id."""
    out: dict[SysId, _T] = {}
    for (sys_id, _), item in per_vehicle.items():
        cur = out.get(sys_id)
        if cur is None or when(item) > when(cur):
            out[sys_id] = item
    return out


@dataclass(slots=True)
class _Source:
    """Per measurement source (kind, system id, ICAO, operation, vehicle address): its
    statistics, and whether no operation flies its system id (as of an airspace version)."""

    stats: TelemetryStats
    airspace_version: int = -1
    unknown: bool = False


@dataclass(frozen=True, slots=True, kw_only=True)
class UsmEvent:
    t_s: float
    kind: str
    text: str


class Usm(RecommendationLifecycle):
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
    ) -> None:
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
        self._lane_stats = _LaneStats()  # per lane source index
        self._lane_unknown: list[bool] = []  # per index: no operation flies its system id
        self._lane_any_unknown = False
        self._lane_version = -1  # the airspace version of _lane_unknown
        self._threat_sinks: list[Callable[[list[Threat]], Awaitable[None]]] = []
        self._answer_sinks: list[Callable[[Recommendation, bool], Awaitable[None]]] = []
        self._operators: list[OperatorPort] = []
        self._geofence_listeners: list[Callable[[Sequence[Geofence]], Awaitable[None]]] = []
        # per vehicle, as health: (system id, where it was first heard)
        self.statuses: dict[tuple[SysId, str], VehicleStatus] = {}
        # per vehicle: (system id, where it was first heard), see LinkHealth.vehicle
        self.health: dict[tuple[SysId, str], LinkHealth] = {}
        self.threats: dict[ThreatId, Threat] = {}
        self.threat_log: list[Threat] = []
        self.recommendations: dict[RecommendationId, RecommendationRecord] = {}
        self._telemetry: dict[str, TelemetryStats] = {}
        self._sources: dict[tuple[object, ...], _Source] = {}
        self._first_alt: dict[SysId, float] = {}
        self.events: deque[UsmEvent] = deque(maxlen=self.config.event_log_size)
        self._hazard_seen: dict[tuple[ThreatKind, str], float] = {}
        self._hazard_seq = itertools.count(1)
        self._tasks: set[asyncio.Task[None]] = set()
        self.counters: dict[str, int] = {
            "measurements": 0,
            "unknown_vehicle_measurements": 0,
            "hazards": 0,
            "hazards_coalesced": 0,
            "answers_refused": 0,
            "uploads_ok": 0,
            "uploads_failed": 0,
        }

    # ---- wiring ---------------------------------------------------------------------------
    def attach_vehicles(self, port: VehiclePort) -> None:
        self._vehicles = port

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

    def attach_threat_sink(self, sink: Callable[[list[Threat]], Awaitable[None]]) -> None:
        """Emergency Management's input."""
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
            if sys_id is not None and sys_id not in self._first_alt:
                self._first_alt[sys_id] = m.alt_amsl_m
            key = f"{m.source.value}:" + (
                str(sys_id) if sys_id is not None else (m.icao24 or m.operation_id or "?")
            )
            if m.vehicle:
                key += f"@{m.vehicle}"
            seen = self._sources[src] = _Source(self._telemetry.setdefault(key, TelemetryStats()))
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
        statistics, the first altitude per system id), then to the lane sinks (tracking) or,
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
            self._new_lane_sources(lane, values)
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

    def _new_lane_sources(self, lane: PositionLane, values: list[float]) -> None:
        """Statistics for the lane sources registered since the last burst, and the first
        altitude of a new system id as :meth:`on_measurement` takes it (the first report of
        its first source)."""
        stats = self._lane_stats
        known = stats.size
        sources = lane.sources
        for src in sources[known:]:
            stats.append(f"telemetry:{src.sys_id}" + (f"@{src.vehicle}" if src.vehicle else ""))
        self._lane_version = -1  # flags for the new sources too
        seen: set[int] = set()
        for at in range(0, len(values), LANE_STRIDE):
            i = int(values[at])
            if i >= known and i not in seen:
                seen.add(i)
                sys_id = sources[i].sys_id
                if sys_id not in self._first_alt:
                    self._first_alt[sys_id] = values[at + _LANE_ALT]

    def on_status(self, s: VehicleStatus) -> None:
        self.statuses[(s.sys_id, s.vehicle)] = s
        op = self.airspace.by_sys_id(s.sys_id)
        if op is None:
            return
        state = op.state
        if s.armed and s.mode in (FlightMode.MISSION, FlightMode.TAKEOFF, FlightMode.GUIDED):
            state = OperationState.ACTIVE
        elif s.armed and s.mode is FlightMode.HOLD and op.state is OperationState.ACTIVE:
            # a hold the UTM did not ask for is still an active flight
            state = OperationState.ACTIVE
        elif not s.armed and op.state is OperationState.ACTIVE and s.landed:
            state = OperationState.LANDED
        if state is not op.state and op.state is not OperationState.SUSPENDED:
            self.airspace.set_state(op.id, state)

    def on_link_health(self, h: LinkHealth) -> None:
        self.health[(h.sys_id, h.vehicle)] = h

    def statuses_by_sys_id(self) -> dict[SysId, VehicleStatus]:
        """One status per system id: of the vehicles flying it, the latest report."""
        return _latest_per_sys_id(self.statuses, lambda s: s.t_s)

    def health_by_sys_id(self) -> dict[SysId, LinkHealth]:
        """One link health per system id: of the vehicles flying it, the most recently heard
        (the one an operation naming that system id is flying now)."""
        return _latest_per_sys_id(self.health, lambda h: h.last_heard_t_s)

    def on_vehicle(self, v: object) -> None:
        """A newly heard vehicle: with no operation for its system id, download its mission and
        file an operation from it (paper: operations come from the pilots' ground stations)."""
        key = getattr(v, "key", None)
        sys_id = getattr(key, "sys_id", None)
        self.log_event("vehicle", f"vehicle discovered: sysid {sys_id}")
        if sys_id is None or self.airspace.by_sys_id(SysId(int(sys_id))) is not None:
            return
        download = getattr(self._vehicles, "download_mission", None)
        if download is None:
            return
        autopilot = getattr(v, "autopilot", Autopilot.UNKNOWN)
        kind = getattr(v, "vehicle_kind", None) or VehicleKind.MULTIROTOR
        self._spawn(self._operation_from_vehicle(SysId(int(sys_id)), autopilot, kind, download))

    async def _operation_from_vehicle(
        self,
        sys_id: SysId,
        autopilot: Autopilot,
        kind: VehicleKind,
        download: Callable[[SysId], Awaitable[Sequence[object]]],
    ) -> None:
        try:
            items = await download(sys_id)
        except Exception as exc:  # the link's own error types; the vehicle may not answer
            self.log_event("vehicle", f"sysid {sys_id}: mission download failed: {exc}")
            return
        home_alt = self._first_alt.get(sys_id)
        plan = mission_to_plan(
            items,
            OperationId(f"sys{sys_id}"),
            t0_s=self.clock.now_s(),
            cruise_speed_mps=self.config.default_cruise_speed_mps,
            home_alt_amsl_m=home_alt,
            skip_first=autopilot is Autopilot.ARDUPILOT,
        )
        if plan is None:
            self.log_event("vehicle", f"sysid {sys_id}: no waypoints in its mission: no operation")
            return
        if self.airspace.by_sys_id(sys_id) is not None:  # filed meanwhile (scenario, MQTT)
            return
        op = Operation(
            id=plan.operation_id,
            icao24=None,
            sys_id=sys_id,
            priority=self.config.default_priority,
            plan=plan,
            vehicle_kind=kind,
            cruise_speed_mps=self.config.default_cruise_speed_mps,
            flight_geometry_m=self.config.default_flight_geometry_m,
            operational_volume_m=self.config.default_operational_volume_m,
            conops="from vehicle mission",
            autopilot=autopilot,
        )
        try:
            self.airspace.add_operation(op)
        except AirspaceError as exc:
            self.log_event("vehicle", f"sysid {sys_id}: {exc}")
            return
        self.log_event(
            "operation", f"{op.id} filed from sysid {sys_id}'s mission ({len(plan.waypoints)} wp)"
        )

    def on_hazard(self, h: HazardReport) -> None:
        """A hazard from outside Monitoring becomes a threat for EM, coalesced per
        (kind, UAS) within the cooldown so a flapping GNSS does not storm the operator."""
        self.counters["hazards"] += 1
        op_id = h.operation_id
        if op_id is None and h.sys_id is not None:
            op = self.airspace.by_sys_id(h.sys_id)
            op_id = op.id if op is not None else None
        key = (h.kind, op_id or (h.source or "airspace") + ":" + (h.area.id if h.area else ""))
        last = self._hazard_seen.get(key)
        if last is not None and h.t_s - last < self.config.hazard_cooldown_s:
            self.counters["hazards_coalesced"] += 1
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
        self._spawn(self.on_threats([threat]))

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
                self.threat_log.append(t)
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

    def _spawn(self, coro: Awaitable[None]) -> None:
        task = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            _log.error("USM task failed", exc_info=task.exception())

    async def drain(self) -> None:
        """Wait for spawned work (uploads, hazard forwarding) to finish."""
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)

    async def close(self) -> None:
        for t in list(self._tasks):
            t.cancel()
        await asyncio.gather(*list(self._tasks), return_exceptions=True)
