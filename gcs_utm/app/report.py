"""The run report: what a scenario run planned, decided and flew, as typed frozen dataclasses
with units in the names, serialised to the JSON that ``gcs-utm plot`` and the evaluation read.

Times in the report are seconds after the scenario's t0 (``*_at_s``, waypoint times); positions
are WGS84 degrees and metres AMSL. ``to_json`` gives the JSON layout field by field (the field
names are the JSON keys), so a changed field is a type error in every reader, not a missing key.
Loss of separation is judged as Monitoring judges it, on the effective minima of each pair
(operational volumes included: :mod:`gcs_utm.core.monitoring.loss`), on the tracks
the UTM had (``separation``) and on the simulated vehicles' true positions (``truth``).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.loss import separation_ratio
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Geofence,
    GeofenceShape,
    Operation,
    OperationId,
    Threat,
    TrackId,
)
from gcs_utm.scenario import Scenario

from .truth import (
    SimVehicle,
    TruthIntrusion,
    TruthPair,
    TruthReport,
    finite,
    inside_fence,
    truth,
)
from .wiring import Runtime, TrackSample

__all__ = [
    "Report",
    "SimVehicle",
    "TruthIntrusion",
    "TruthPair",
    "TruthReport",
    "build_report",
    "truth",
]

Json = dict[str, Any]


@dataclass(frozen=True, slots=True, kw_only=True)
class LatLonJson:
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionJson:
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float


@dataclass(frozen=True, slots=True, kw_only=True)
class OriginReport:
    lat_deg: float
    lon_deg: float
    ground_elevation_amsl_m: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SeparationMinimum:
    mode: str
    horizontal_m: float
    vertical_m: float
    safety_distance_m: float


WaypointRow = tuple[float, float, float, float]
"""(lat_deg, lon_deg, alt_amsl_m, t_s after t0) of one plan waypoint."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PlanReport:
    version: int
    reason: str
    waypoints: tuple[WaypointRow, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class OperationReport:
    id: str
    priority: int
    conops: str
    vehicle: str
    state: str
    flight_geometry_m: float
    operational_volume_m: float
    start_delay_s: float
    plans: tuple[PlanReport, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class GeofenceReport:
    id: str
    shape: str
    min_alt_amsl_m: float
    max_alt_amsl_m: float
    start_s: float | None
    end_s: float | None
    kind: str
    reason: str
    exempt: tuple[str, ...]
    center: LatLonJson | None = None
    radius_m: float | None = None
    vertices: tuple[LatLonJson, ...] | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class ThreatReport:
    id: str
    kind: str
    uas: tuple[str, ...]
    status: str
    detected_at_s: float | None
    predicted_event_at_s: float | None
    geofence: str | None
    closest_approach_m: float | None
    closest_approach_at_s: float | None
    position: PositionJson | None
    message: str


@dataclass(frozen=True, slots=True, kw_only=True)
class AlternativeReport:
    maneuver: str
    cost: float
    risk: float
    selected: bool
    waypoints: tuple[WaypointRow, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class RecommendationReport:
    id: str
    version: int
    uas: str
    threat: str
    threat_kind: str
    threat_detected_at_s: float | None
    maneuver: str | None
    cost: float | None
    risk: float | None
    latency_ms: float  # wall clock (0 in fast time, where computing takes no simulated time)
    created_at_s: float | None
    deadline_at_s: float | None
    decision: str
    answered_by: str
    answered_via: str
    chosen_alternative_index: int | None
    state: str
    uploaded: bool
    verified: bool
    error: str
    # every version's proposal and state change: (t_s after t0, text)
    history: tuple[tuple[float | None, str], ...]
    alternatives: tuple[AlternativeReport, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class SeparationReport:
    """One pair on the UTM's tracks: the verdict against ``minimum_*`` (the pair's effective
    minima, the only minima it is judged by); ``*_at_closest_m`` at the instant of the
    smallest normalised separation ``min_ratio`` (below 1: a loss)."""

    pair: tuple[str, str]
    minimum_horizontal_m: float
    minimum_vertical_m: float
    min_horizontal_m: float | None
    min_distance_m: float | None
    min_ratio: float | None
    horizontal_at_closest_m: float | None
    vertical_at_closest_m: float | None
    loss_of_separation: bool


@dataclass(frozen=True, slots=True, kw_only=True)
class IntrusionReport:
    uas: str
    geofence: str
    first_at_s: float
    samples_inside: int


@dataclass(frozen=True, slots=True, kw_only=True)
class EscalationReport:
    at_s: float | None
    text: str


TrackRow = tuple[float, float, float, float]
"""(t_s after t0, lat_deg, lon_deg, alt_amsl_m) of one sampled track state."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Report:
    """One scenario run. ``speed`` is the speed-up factor, or ``"max"`` for fast time;
    ``wall_clock_s`` and ``latency_ms`` are the only fields measured on the wall clock."""

    scenario: str
    description: str
    speed: float | str
    wall_clock_s: float
    origin: OriginReport
    separation_minimum: SeparationMinimum
    operations: tuple[OperationReport, ...]
    geofences: tuple[GeofenceReport, ...]
    threats: tuple[ThreatReport, ...]
    recommendations: tuple[RecommendationReport, ...]
    tracks: Mapping[str, tuple[TrackRow, ...]]
    telemetry: Mapping[str, Mapping[str, float | int]]
    counters: Mapping[str, int]
    adsb: Mapping[str, Any]  # ADS-B feeds' and the MAVLink ADSB_VEHICLE relay's counts
    separation: tuple[SeparationReport, ...]
    geofence_intrusions: tuple[IntrusionReport, ...]
    escalations: tuple[EscalationReport, ...] = ()
    truth: TruthReport | None = None
    operator_quit: bool = False  # the operator ended the run from the dashboard (q)

    def to_json(self) -> Json:
        """The JSON object (``json.dumps``-ready) of the report; ``truth`` only when known."""
        out = _jsonable(self)
        assert isinstance(out, dict)
        if self.truth is None:
            del out["truth"]
        return out

    def comparable(self) -> Json:
        """The JSON object less what differs between two runs of one scenario however
        deterministic they are: the fields measured on the wall clock, and the loopback port
        numbers the OS chose (telemetry is keyed ``source:sysid@host:port``: kept up to the
        ``@``)."""
        out = self.to_json()
        out.pop("wall_clock_s")
        for rec in out["recommendations"]:
            rec.pop("latency_ms")
        telemetry = {}
        for key, tele in out["telemetry"].items():
            for field in ("mean_delay_ms", "min_delay_ms", "max_delay_ms"):
                tele.pop(field, None)
            telemetry[key.split("@", 1)[0]] = tele
        out["telemetry"] = telemetry
        return out


def _jsonable(obj: object) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out = {}
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if value is None and f.name in ("center", "radius_m", "vertices"):
                continue  # a geofence has either a centre and radius or vertices
            out[f.name] = _jsonable(value)
        return out
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    return obj


# ---- building ------------------------------------------------------------------------------


def _rel(t_s: float | None, t0: float) -> float | None:
    return None if t_s is None else round(t_s - t0, 3)


def _plan(plan: FlightPlan, t0: float) -> PlanReport:
    return PlanReport(
        version=plan.version,
        reason=plan.reason,
        waypoints=tuple(
            (w.lat_deg, w.lon_deg, round(w.alt_amsl_m, 2), round(w.t_s - t0, 3))
            for w in plan.waypoints
        ),
    )


def _geofence(g: Geofence, t0: float) -> GeofenceReport:
    cylinder = g.shape is GeofenceShape.CYLINDER and g.center is not None
    return GeofenceReport(
        id=g.id,
        shape=g.shape.value,
        min_alt_amsl_m=g.min_alt_amsl_m,
        max_alt_amsl_m=g.max_alt_amsl_m,
        start_s=_rel(g.start_t_s, t0),
        end_s=_rel(g.end_t_s, t0),
        kind=g.kind.value,
        reason=g.reason,
        exempt=tuple(g.exempt),
        center=LatLonJson(lat_deg=g.center.lat_deg, lon_deg=g.center.lon_deg)
        if cylinder and g.center is not None
        else None,
        radius_m=g.radius_m if cylinder else None,
        vertices=None
        if cylinder
        else tuple(LatLonJson(lat_deg=v.lat_deg, lon_deg=v.lon_deg) for v in g.vertices),
    )


def _threat(t: Threat, t0: float) -> ThreatReport:
    return ThreatReport(
        id=t.id,
        kind=t.kind.value,
        uas=tuple(t.uas_ids),
        status=t.status.value,
        detected_at_s=_rel(t.detected_at_s, t0),
        predicted_event_at_s=_rel(t.predicted_event_at_s, t0),
        geofence=t.geofence_id,
        closest_approach_m=t.closest_approach_m,
        closest_approach_at_s=_rel(t.closest_approach_t_s, t0),
        position=None
        if t.position is None
        else PositionJson(
            lat_deg=t.position.lat_deg,
            lon_deg=t.position.lon_deg,
            alt_amsl_m=t.position.alt_amsl_m,
        ),
        message=t.message,
    )


def _recommendations(rt: Runtime, t0: float) -> tuple[RecommendationReport, ...]:
    out = []
    for record in rt.usm.recommendations.values():
        rec = record.rec
        options = ([rec.selected] if rec.selected is not None else []) + list(rec.alternatives)
        alts = tuple(
            AlternativeReport(
                maneuver=alt.maneuver.value,
                cost=round(alt.cost, 4),
                risk=round(alt.risk, 4),
                selected=i == 0 and rec.selected is not None,
                waypoints=() if alt.plan is None else _plan(alt.plan, t0).waypoints,
            )
            for i, alt in enumerate(options)
        )
        maneuver = (
            rec.selected.maneuver.value
            if rec.selected is not None
            else (rec.command.kind.value if rec.command is not None else None)
        )
        out.append(
            RecommendationReport(
                id=rec.id,
                version=rec.version,
                uas=rec.operation_id,
                threat=rec.threat_id,
                threat_kind=rec.threat_kind.value,
                threat_detected_at_s=_rel(record.threat_detected_at_s, t0),
                maneuver=maneuver,
                cost=None if rec.selected is None else round(rec.selected.cost, 4),
                risk=None if rec.selected is None else round(rec.selected.risk, 4),
                latency_ms=round(record.latency_ms, 3),
                created_at_s=_rel(rec.created_t_s, t0),
                deadline_at_s=_rel(rec.deadline_t_s, t0),
                decision=record.decision or rec.state.value,
                answered_by=record.answered_by,
                answered_via=record.answered_via,
                chosen_alternative_index=record.chosen_index,
                state=rec.state.value,
                uploaded=record.uploaded,
                verified=record.verified,
                error=record.error,
                history=tuple((_rel(t, t0), text) for t, text in record.history),
                alternatives=alts,
            )
        )
    return tuple(out)


def build_report(
    rt: Runtime,
    scenario: Scenario,
    *,
    wall_s: float,
    speed: float | str,
    vehicles: Sequence[SimVehicle] = (),
    operator_quit: bool = False,
) -> Report:
    t0 = scenario.t0_s
    ops = rt.airspace.operations
    mon = rt.settings.monitoring
    delays = {v.operation_id: v.start_delay_s for v in scenario.vehicles}
    telemetry_speed = speed if isinstance(speed, float) else 1.0
    return Report(
        scenario=scenario.name,
        description=scenario.description,
        speed=speed,
        wall_clock_s=round(wall_s, 3),
        origin=OriginReport(
            lat_deg=scenario.frame.origin_lat_deg,
            lon_deg=scenario.frame.origin_lon_deg,
            ground_elevation_amsl_m=scenario.frame.ground_elevation_amsl_m,
        ),
        separation_minimum=SeparationMinimum(
            mode=mon.separation_mode,
            horizontal_m=mon.separation_horizontal_m,
            vertical_m=mon.separation_vertical_m,
            safety_distance_m=mon.safety_distance_m,
        ),
        operations=tuple(
            OperationReport(
                id=op.id,
                priority=op.priority,
                conops=op.conops,
                vehicle=op.vehicle_kind.value,
                state=op.state.value,
                flight_geometry_m=op.flight_geometry_m,
                operational_volume_m=op.operational_volume_m,
                start_delay_s=delays.get(op.id, 0.0),
                plans=tuple(_plan(p, t0) for p in rt.plan_history.get(op.id, [op.plan])),
            )
            for op in ops.values()
        ),
        geofences=tuple(_geofence(g, t0) for g in rt.geofence_history.values()),
        threats=tuple(_threat(t, t0) for t in rt.usm.threat_log),
        recommendations=_recommendations(rt, t0),
        tracks={
            tid: tuple((round(s[0] - t0, 3), s[1], s[2], round(s[3], 2)) for s in samples)
            for tid, samples in rt.samples.items()
        },
        telemetry={k: v.as_dict(telemetry_speed) for k, v in rt.usm.telemetry.items()},
        counters=dict(rt.usm.counters),
        adsb=rt.surveillance.report(rt.hub.adsb_relay.counters),
        separation=separation(rt.samples, ops, mon),
        geofence_intrusions=intrusions(rt.samples, rt.geofence_history, rt.frame, t0),
        escalations=tuple(
            EscalationReport(at_s=_rel(e.t_s, t0), text=e.text)
            for e in rt.usm.events
            if e.kind == "escalation"
        ),
        truth=truth(vehicles, scenario, rt.frame, mon, geofences=rt.geofence_history)
        if vehicles
        else None,
        operator_quit=operator_quit,
    )


def separation(
    samples: Mapping[TrackId, Sequence[TrackSample]],
    ops: Mapping[OperationId, Operation],
    mon: MonitoringConfig,
) -> tuple[SeparationReport, ...]:
    """Per UAS pair, from the tracks sampled during the run at the same sample instants (both
    tracks' states at most one sample period apart): the verdict against the pair's one set
    of effective minima (Monitoring's), and the closest approach at the instant of the
    smallest normalised separation (:func:`~gcs_utm.core.monitoring.loss.separation_ratio`),
    with the horizontal and vertical distances at that instant."""
    out = []
    ids = sorted(i for i in samples if OperationId(i) in ops)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            h_min, v_min = mon.effective_minima(
                ops[OperationId(a)].operational_volume_m, ops[OperationId(b)].operational_volume_m
            )
            best_h = best_3d = best_ratio = math.inf
            at: tuple[float, float, float] | None = None  # (t_s, dh, dv) at the best ratio
            for s in samples[a]:
                match = _nearest(samples[b], round(s[0], 1))
                if match is None:
                    continue
                dh = math.hypot(s[4] - match[4], s[5] - match[5])
                dv = abs(s[3] - match[3])
                best_h = min(best_h, dh)
                best_3d = min(best_3d, math.hypot(dh, dv))
                ratio = float(separation_ratio(dh, dv, h_min, v_min, spherical=mon.spherical))
                if ratio < best_ratio:
                    best_ratio, at = ratio, (s[0], dh, dv)
            out.append(
                SeparationReport(
                    pair=(a, b),
                    minimum_horizontal_m=h_min,
                    minimum_vertical_m=v_min,
                    min_horizontal_m=finite(best_h),
                    min_distance_m=finite(best_3d),
                    min_ratio=None if at is None else round(best_ratio, 4),
                    horizontal_at_closest_m=None if at is None else round(at[1], 2),
                    vertical_at_closest_m=None if at is None else round(at[2], 2),
                    loss_of_separation=best_ratio < 1.0,
                )
            )
    return tuple(out)


def _nearest(samples: Sequence[TrackSample], t_s: float) -> TrackSample | None:
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


def intrusions(
    samples: Mapping[TrackId, Sequence[TrackSample]],
    geofences: Mapping[str, Geofence],
    frame: LocalFrame,
    t0: float,
) -> tuple[IntrusionReport, ...]:
    """Actual (not predicted) geofence intrusions of the tracks flown."""
    out = []
    for tid, rows in samples.items():
        for g in geofences.values():
            if not g.applies_to(tid):
                continue
            lf = localise(g, frame)
            inside = [s for s in rows if g.active_at(s[0]) and inside_fence(lf, s[4], s[5], s[3])]
            if inside:
                out.append(
                    IntrusionReport(
                        uas=tid,
                        geofence=g.id,
                        first_at_s=round(inside[0][0] - t0, 3),
                        samples_inside=len(inside),
                    )
                )
    return tuple(out)
