"""The run report: what a scenario run planned, decided and flew, as typed frozen dataclasses
with units in the names, serialised to the JSON that ``gcs-utm plot`` and the evaluation read.

Times in the report are seconds after the scenario's t0 (``*_at_s``, waypoint times); positions
are WGS84 degrees and metres AMSL. ``to_json`` gives the JSON layout field by field (the field
names are the JSON keys), so a changed field is a type error in every reader, not a missing key.
Loss of separation is judged as Monitoring judges it, on the effective minima of each pair
(operational volumes included: :func:`gcs_utm.core.monitoring.loss.is_loss`), on the tracks
the UTM had (``separation``) and on the simulated vehicles' true positions (``truth``).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.geometry import points_in_edges
from gcs_utm.core.monitoring.loss import is_loss
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

from .wiring import Runtime, TrackSample

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
    pair: tuple[str, str]
    min_horizontal_m: float | None
    min_vertical_when_close_m: float | None
    min_distance_m: float | None
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


@dataclass(frozen=True, slots=True, kw_only=True)
class TruthPair:
    pair: tuple[str, str]
    min_distance_m: float | None
    loss_of_separation: bool


@dataclass(frozen=True, slots=True, kw_only=True)
class TruthReport:
    pairs: tuple[TruthPair, ...]


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


class SimVehicle(Protocol):
    """What the report reads of a simulated vehicle (``sitl.Vehicle``)."""

    @property
    def sys_id(self) -> int: ...

    @property
    def position_history(self) -> Sequence[tuple[float, float, float, float]]: ...


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
        truth=truth(vehicles, scenario, rt.frame, mon, flying_until_t_s=_plan_ends(rt))
        if vehicles
        else None,
        operator_quit=operator_quit,
    )


def separation(
    samples: Mapping[TrackId, Sequence[TrackSample]],
    ops: Mapping[OperationId, Operation],
    mon: MonitoringConfig,
) -> tuple[SeparationReport, ...]:
    """Minimum achieved distances per UAS pair, from the tracks sampled during the run at the
    same sample instants (both tracks' states are at most one sample period apart)."""
    out = []
    ids = sorted(i for i in samples if OperationId(i) in ops)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            ov_a = ops[OperationId(a)].operational_volume_m
            ov_b = ops[OperationId(b)].operational_volume_m
            sa = {round(s[0], 1): s for s in samples[a]}
            best_h = best_v = best_3d = math.inf
            loss = False
            for key, s in sa.items():
                match = _nearest(samples[b], key)
                if match is None:
                    continue
                dh = math.hypot(s[4] - match[4], s[5] - match[5])
                dv = abs(s[3] - match[3])
                best_h = min(best_h, dh)
                best_v = min(best_v, dv) if dh < mon.separation_horizontal_m * 3 else best_v
                best_3d = min(best_3d, math.hypot(dh, dv))
                loss = loss or is_loss(mon, dh, dv, ov_a, ov_b)
            out.append(
                SeparationReport(
                    pair=(a, b),
                    min_horizontal_m=_finite(best_h),
                    min_vertical_when_close_m=_finite(best_v),
                    min_distance_m=_finite(best_3d),
                    loss_of_separation=loss,
                )
            )
    return tuple(out)


def _finite(x: float) -> float | None:
    return None if math.isinf(x) else round(x, 2)


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
            inside = [s for s in rows if g.active_at(s[0]) and _inside(lf, s[4], s[5], s[3])]
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


def _inside(lf: Any, east_m: float, north_m: float, alt_amsl_m: float) -> bool:
    """Is a point inside a localised geofence (altitude band, then cylinder or polygon)?"""
    if not lf.z_lo <= alt_amsl_m <= lf.z_hi:
        return False
    if lf.center is not None:
        return bool(math.hypot(east_m - lf.center[0], north_m - lf.center[1]) <= lf.radius_m)
    inside = points_in_edges(np.array([east_m]), np.array([north_m]), lf.edges)
    return bool(inside[0])


def _plan_ends(rt: Runtime) -> dict[str, float]:
    """End time (t_s) of each operation's latest plan."""
    return {
        op_id: plans[-1].waypoints[-1].t_s
        for op_id, plans in rt.plan_history.items()
        if plans and plans[-1].waypoints
    }


def truth(
    vehicles: Sequence[SimVehicle],
    scenario: Scenario,
    frame: LocalFrame,
    mon: MonitoringConfig,
    *,
    flying_until_t_s: Mapping[str, float] | None = None,
) -> TruthReport:
    """Ground truth from the simulated vehicles (their true positions, not the tracks), in
    true metres (see :func:`_tangent_plane_m`) and metres AMSL, while both operations of a
    pair are in progress: up to the end of the earlier one's latest plan
    (``flying_until_t_s``, by operation id). A simulated vehicle stays in the air after its
    mission (a fixed wing circles its last waypoint); a real operation ends there.

    The vehicles record their position once a simulated second; between two records each
    moves linearly, so one vehicle's records are interpolated at the other's record times and
    every interval between records is checked exactly (closest approach and the instants in
    loss of separation of linear relative motion), not only the sampled instants."""
    by_sys = {int(v.sys_id): v for v in vehicles}
    ops = {int(op.sys_id): op for op in scenario.operations if op.sys_id is not None}
    local = {s: _local_history(frame, by_sys[s].position_history) for s in by_sys if s in ops}
    pairs = []
    ids = sorted(local)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            min_h, min_v = mon.effective_minima(
                ops[a].operational_volume_m, ops[b].operational_volume_m
            )
            until = min(
                (flying_until_t_s or {}).get(ops[a].id, math.inf),
                (flying_until_t_s or {}).get(ops[b].id, math.inf),
            )
            best, loss = _pair_truth(
                local[a][local[a][:, 0] <= until] if len(local[a]) else local[a],
                local[b],
                min_h,
                min_v,
                spherical=mon.spherical,
            )
            pairs.append(
                TruthPair(
                    pair=(ops[a].id, ops[b].id),
                    min_distance_m=_finite(best),
                    loss_of_separation=loss,
                )
            )
    return TruthReport(pairs=tuple(pairs))


def _local_history(
    frame: LocalFrame, history: Sequence[tuple[float, float, float, float]]
) -> npt.NDArray[np.float64]:
    """(K, 4) rows of t_s, east_m, north_m, alt_amsl_m."""
    if not history:
        return np.zeros((0, 4))
    h = np.asarray(history, dtype=np.float64)
    east, north = _tangent_plane_m(frame.origin_lat_deg, frame.origin_lon_deg, h[:, 1], h[:, 2])
    return np.column_stack((h[:, 0], east, north, h[:, 3]))


_WGS84_A_M = 6378137.0
_WGS84_E2 = 6.69437999014e-3


def _tangent_plane_m(
    lat0_deg: float,
    lon0_deg: float,
    lat_deg: npt.NDArray[np.float64],
    lon_deg: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(east_m, north_m) in the tangent plane at the origin, through Earth-centred
    coordinates: true metres (no map projection's scale factor), so the truth does not share
    the UTM frame the service computes in."""

    def ecef(lat: npt.NDArray[np.float64], lon: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        la, lo = np.radians(lat), np.radians(lon)
        n = _WGS84_A_M / np.sqrt(1.0 - _WGS84_E2 * np.sin(la) ** 2)
        return np.stack(
            (
                n * np.cos(la) * np.cos(lo),
                n * np.cos(la) * np.sin(lo),
                n * (1 - _WGS84_E2) * np.sin(la),
            )
        )

    o = ecef(np.array([lat0_deg]), np.array([lon0_deg]))[:, 0]
    d = ecef(lat_deg, lon_deg) - o[:, None]
    la, lo = math.radians(lat0_deg), math.radians(lon0_deg)
    east = -math.sin(lo) * d[0] + math.cos(lo) * d[1]
    north = (
        -math.sin(la) * math.cos(lo) * d[0]
        - math.sin(la) * math.sin(lo) * d[1]
        + math.cos(la) * d[2]
    )
    return east, north


def _pair_truth(
    a: npt.NDArray[np.float64],
    b: npt.NDArray[np.float64],
    min_h_m: float,
    min_v_m: float,
    *,
    spherical: bool,
) -> tuple[float, bool]:
    """(minimum 3D distance m, loss of separation) while both vehicles were recorded."""
    if len(a) < 2 or len(b) < 2:
        return math.inf, False
    t = a[:, 0]
    both = (t >= b[0, 0]) & (t <= b[-1, 0])
    if both.sum() < 2:
        return math.inf, False
    t = t[both]
    rel = a[both, 1:] - np.column_stack([np.interp(t, b[:, 0], b[:, k]) for k in (1, 2, 3)])
    best = math.inf
    loss = False
    for k in range(len(rel) - 1):
        r0 = (float(rel[k, 0]), float(rel[k, 1]), float(rel[k, 2]))
        d = (
            float(rel[k + 1, 0]) - r0[0],
            float(rel[k + 1, 1]) - r0[1],
            float(rel[k + 1, 2]) - r0[2],
        )
        dd = d[0] ** 2 + d[1] ** 2 + d[2] ** 2
        u = (
            0.0
            if dd == 0.0
            else max(0.0, min(1.0, -(r0[0] * d[0] + r0[1] * d[1] + r0[2] * d[2]) / dd))
        )
        best = min(best, math.dist((0.0, 0.0, 0.0), tuple(r0[i] + u * d[i] for i in range(3))))
        loss = loss or _segment_in_loss(r0, d, min_h_m, min_v_m, spherical=spherical)
    return best, loss


def _below(a: float, b: float, c: float) -> tuple[float, float]:
    """The interval of u where a u^2 + b u + c < 0 (a >= 0); empty when lo >= hi."""
    if a <= 1e-12:
        if abs(b) <= 1e-12:
            return (-math.inf, math.inf) if c < 0.0 else (math.inf, -math.inf)
        root = -c / b
        return (-math.inf, root) if b > 0.0 else (root, math.inf)
    disc = b * b - 4.0 * a * c
    if disc <= 0.0:
        return math.inf, -math.inf
    s = math.sqrt(disc)
    return (-b - s) / (2.0 * a), (-b + s) / (2.0 * a)


def _segment_in_loss(
    r0: tuple[float, float, float],
    d: tuple[float, float, float],
    min_h_m: float,
    min_v_m: float,
    *,
    spherical: bool,
) -> bool:
    """Is the relative position r0 + u d inside the minima for some u in [0, 1]?"""
    if spherical:
        lo, hi = _below(
            d[0] ** 2 + d[1] ** 2 + d[2] ** 2,
            2.0 * (r0[0] * d[0] + r0[1] * d[1] + r0[2] * d[2]),
            r0[0] ** 2 + r0[1] ** 2 + r0[2] ** 2 - min_h_m**2,
        )
        return max(0.0, lo) < min(1.0, hi)
    h_lo, h_hi = _below(
        d[0] ** 2 + d[1] ** 2,
        2.0 * (r0[0] * d[0] + r0[1] * d[1]),
        r0[0] ** 2 + r0[1] ** 2 - min_h_m**2,
    )
    v_lo, v_hi = _below(d[2] ** 2, 2.0 * r0[2] * d[2], r0[2] ** 2 - min_v_m**2)
    return max(0.0, h_lo, v_lo) < min(1.0, h_hi, v_hi)
