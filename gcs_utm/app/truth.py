"""Ground truth of a run: what the simulated vehicles actually flew, judged pair by pair from
take-off to landing and against the geofences, on their true positions.

A vehicle is *airborne* while its true altitude is more than :data:`AIRBORNE_ABOVE_HOME_M`
above its home (take-off to landing), whatever its plan says: a multirotor hovering at its
last waypoint or a fixed wing circling it after its plan has ended is still traffic. Every
pair of airborne vehicles is judged under the pair's effective minima as Monitoring computes
them (:meth:`gcs_utm.core.monitoring.config.MonitoringConfig.effective_minima`, operational
volumes included) and the same normalised separation
(:func:`gcs_utm.core.monitoring.loss.separation_ratio`: below 1 is a loss).

Positions are in true metres (a tangent plane at the airspace origin through Earth-centred
coordinates, :func:`tangent_plane_m`, not the UTM grid the service computes in) and metres
AMSL. The vehicles record their position once a simulated second; between two records each
moves linearly, so one vehicle's records are interpolated at the other's record times and
every interval is checked exactly (the instants in loss of linear relative motion), not only
the sampled instants.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.fences import localise
from gcs_utm.core.monitoring.geometry import points_in_edges
from gcs_utm.core.monitoring.loss import separation_ratio
from gcs_utm.geo import LocalFrame
from gcs_utm.model import Geofence
from gcs_utm.scenario import Scenario

FloatArray = npt.NDArray[np.float64]

AIRBORNE_ABOVE_HOME_M = 0.5
"""A vehicle more than this above its home is in the air (the simulated vehicles sit exactly
at their home altitude on the ground)."""
_COARSE_STEPS = 16  # samples per interval for the closest normalised separation, then refined
_REFINE_ITERATIONS = 40


class SimVehicle(Protocol):
    """What the truth reads of a simulated vehicle (``sitl.Vehicle``)."""

    @property
    def sys_id(self) -> int: ...

    @property
    def position_history(self) -> Sequence[tuple[float, float, float, float]]: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class TruthPair:
    """One pair of vehicles, judged while both were airborne. ``minimum_*`` is the one set of
    minima the verdict is taken against; the closest approach is the instant of the smallest
    normalised separation (``min_ratio``: max(dh / h, dv / v), or 3D / safety distance in
    sphere mode), with the horizontal and vertical distances at that instant."""

    pair: tuple[str, str]
    min_distance_m: float | None  # smallest 3D distance (m)
    loss_of_separation: bool
    mode: str = "cylinder"
    minimum_horizontal_m: float | None = None
    minimum_vertical_m: float | None = None
    min_ratio: float | None = None
    closest_at_s: float | None = None
    horizontal_at_closest_m: float | None = None
    vertical_at_closest_m: float | None = None
    first_loss_at_s: float | None = None
    loss_duration_s: float = 0.0


@dataclass(frozen=True, slots=True, kw_only=True)
class TruthIntrusion:
    """A vehicle's true position inside an active geofence that applies to it."""

    uas: str
    geofence: str
    first_at_s: float
    duration_s: float  # time between records, counted from each record found inside
    samples_inside: int


@dataclass(frozen=True, slots=True, kw_only=True)
class TruthReport:
    pairs: tuple[TruthPair, ...]
    intrusions: tuple[TruthIntrusion, ...] = ()


def truth(
    vehicles: Sequence[SimVehicle],
    scenario: Scenario,
    frame: LocalFrame,
    mon: MonitoringConfig,
    *,
    geofences: Mapping[str, Geofence] | None = None,
) -> TruthReport:
    """Ground truth from the simulated vehicles (true positions, not the tracks), every pair
    judged while both are airborne; intrusions into ``geofences`` (UTM frame ``frame``)."""
    by_sys = {int(v.sys_id): v for v in vehicles}
    ops = {int(op.sys_id): op for op in scenario.operations if op.sys_id is not None}
    homes = {int(v.sys_id): v.home.alt_amsl_m for v in scenario.vehicles if v.sys_id is not None}
    local = {s: local_history(frame, by_sys[s].position_history) for s in by_sys if s in ops}
    airborne = {
        s: rows[:, 3] > homes.get(s, -math.inf) + AIRBORNE_ABOVE_HOME_M for s, rows in local.items()
    }
    pairs = []
    ids = sorted(local)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            h_m, v_m = mon.effective_minima(
                ops[a].operational_volume_m, ops[b].operational_volume_m
            )
            judged = judge_pair(
                (local[a], airborne[a]), (local[b], airborne[b]), h_m, v_m, spherical=mon.spherical
            )
            pairs.append(
                _truth_pair(
                    (ops[a].id, ops[b].id), judged, h_m=h_m, v_m=v_m, mon=mon, t0_s=scenario.t0_s
                )
            )
    intrusions: list[TruthIntrusion] = []
    for s in local:
        history = by_sys[s].position_history
        intrusions += _intrusions(
            ops[s].id, history, airborne[s], geofences or {}, frame=frame, t0_s=scenario.t0_s
        )
    return TruthReport(pairs=tuple(pairs), intrusions=tuple(intrusions))


def _truth_pair(
    pair: tuple[str, str],
    j: PairJudgement,
    *,
    h_m: float,
    v_m: float,
    mon: MonitoringConfig,
    t0_s: float,
) -> TruthPair:
    return TruthPair(
        pair=pair,
        min_distance_m=finite(j.min_distance_m),
        loss_of_separation=j.first_loss_t_s is not None,
        mode=mon.separation_mode,
        minimum_horizontal_m=h_m,
        minimum_vertical_m=v_m,
        min_ratio=None if math.isinf(j.min_ratio) else round(j.min_ratio, 4),
        closest_at_s=None if j.closest_t_s is None else round(j.closest_t_s - t0_s, 3),
        horizontal_at_closest_m=finite(j.horizontal_m),
        vertical_at_closest_m=finite(j.vertical_m),
        first_loss_at_s=None if j.first_loss_t_s is None else round(j.first_loss_t_s - t0_s, 3),
        loss_duration_s=round(j.loss_duration_s, 3),
    )


def finite(x: float) -> float | None:
    return None if math.isinf(x) else round(x, 2)


@dataclass(frozen=True, slots=True, kw_only=True)
class PairJudgement:
    """The judgement of one pair in the records' time base (seconds, as recorded)."""

    min_distance_m: float = math.inf
    min_ratio: float = math.inf
    closest_t_s: float | None = None
    horizontal_m: float = math.inf
    vertical_m: float = math.inf
    first_loss_t_s: float | None = None
    loss_duration_s: float = 0.0


def judge_pair(
    a: tuple[FloatArray, npt.NDArray[np.bool_]],
    b: tuple[FloatArray, npt.NDArray[np.bool_]],
    min_h_m: float,
    min_v_m: float,
    *,
    spherical: bool,
) -> PairJudgement:
    """Judge two vehicles' (K, 4) records (t_s, east_m, north_m, alt_amsl_m) with their
    airborne flags, over every interval in which both were airborne at both ends."""
    rows_a, air_a = a
    rows_b, air_b = b
    if len(rows_a) < 2 or len(rows_b) < 2:
        return PairJudgement()
    t = rows_a[:, 0]
    both = (t >= rows_b[0, 0]) & (t <= rows_b[-1, 0])
    if both.sum() < 2:
        return PairJudgement()
    t = t[both]
    b_at = np.column_stack([np.interp(t, rows_b[:, 0], rows_b[:, k]) for k in (1, 2, 3)])
    rel = rows_a[both, 1:] - b_at
    # b airborne at t: both of its neighbouring records airborne
    b_air = np.interp(t, rows_b[:, 0], air_b.astype(np.float64)) > 1.0 - 1e-9
    flying = air_a[both] & b_air
    valid = flying[:-1] & flying[1:]
    if not valid.any():
        return PairJudgement()
    r0 = rel[:-1][valid]
    d = (rel[1:] - rel[:-1])[valid]
    t_start = t[:-1][valid]
    dt = (t[1:] - t[:-1])[valid]
    best_3d = _closest_3d_m(r0, d)
    ratio, closest_t, dh, dv = _closest_ratio(r0, d, (t_start, dt), (min_h_m, min_v_m, spherical))
    first_loss: float | None = None
    duration = 0.0
    for k in range(len(r0)):
        r0k = (float(r0[k, 0]), float(r0[k, 1]), float(r0[k, 2]))
        dk = (float(d[k, 0]), float(d[k, 1]), float(d[k, 2]))
        lo, hi = loss_interval(r0k, dk, min_h_m, min_v_m, spherical=spherical)
        if lo < hi:
            duration += (hi - lo) * float(dt[k])
            if first_loss is None:
                first_loss = float(t_start[k]) + lo * float(dt[k])
    return PairJudgement(
        min_distance_m=best_3d,
        min_ratio=ratio,
        closest_t_s=closest_t,
        horizontal_m=dh,
        vertical_m=dv,
        first_loss_t_s=first_loss,
        loss_duration_s=duration,
    )


def _closest_3d_m(r0: FloatArray, d: FloatArray) -> float:
    dd = np.einsum("ij,ij->i", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(dd > 0.0, -np.einsum("ij,ij->i", r0, d) / dd, 0.0)
    u = np.clip(u, 0.0, 1.0)
    return float(np.min(np.linalg.norm(r0 + u[:, None] * d, axis=1)))


Minima = tuple[float, float, bool]
"""(horizontal_m, vertical_m, spherical) of one pair."""


def _ratio_at(
    r0: FloatArray, d: FloatArray, u: FloatArray, minima: Minima
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(ratio, dh, dv) at fractions ``u`` (broadcast against the rows of r0, d)."""
    min_h_m, min_v_m, spherical = minima
    p = r0[..., None, :] + u[..., None] * d[..., None, :]
    dh = np.hypot(p[..., 0], p[..., 1])
    dv = np.abs(p[..., 2])
    return separation_ratio(dh, dv, min_h_m, min_v_m, spherical=spherical), dh, dv


def _closest_ratio(
    r0: FloatArray,
    d: FloatArray,
    times: tuple[FloatArray, FloatArray],
    minima: Minima,
) -> tuple[float, float, float, float]:
    """(smallest normalised separation, its time, dh and dv then). The ratio is convex along
    an interval (a maximum of norms of linear motion): sampled, then refined by ternary search
    in the best interval. ``times``: each interval's start and length (s)."""
    t_start, dt = times
    grid = np.linspace(0.0, 1.0, _COARSE_STEPS + 1)
    ratio, _, _ = _ratio_at(r0, d, np.broadcast_to(grid, (len(r0), len(grid))), minima)
    k, j = np.unravel_index(int(np.argmin(ratio)), ratio.shape)
    lo = max(0.0, float(grid[j]) - 1.0 / _COARSE_STEPS)
    hi = min(1.0, float(grid[j]) + 1.0 / _COARSE_STEPS)
    rk, dk = r0[k : k + 1], d[k : k + 1]

    def f(u: float) -> float:
        return float(_ratio_at(rk, dk, np.array([[u]]), minima)[0][0, 0])

    for _ in range(_REFINE_ITERATIONS):
        m1, m2 = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
        if f(m1) <= f(m2):
            hi = m2
        else:
            lo = m1
    u = (lo + hi) / 2.0
    r, dh, dv = _ratio_at(rk, dk, np.array([[u]]), minima)
    return float(r[0, 0]), float(t_start[k] + u * dt[k]), float(dh[0, 0]), float(dv[0, 0])


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


def loss_interval(
    r0: tuple[float, float, float],
    d: tuple[float, float, float],
    min_h_m: float,
    min_v_m: float,
    *,
    spherical: bool,
) -> tuple[float, float]:
    """The fractions u in [0, 1] where the relative position r0 + u d is inside the minima,
    as (lo, hi); empty when lo >= hi."""
    if spherical:
        lo, hi = _below(
            d[0] ** 2 + d[1] ** 2 + d[2] ** 2,
            2.0 * (r0[0] * d[0] + r0[1] * d[1] + r0[2] * d[2]),
            r0[0] ** 2 + r0[1] ** 2 + r0[2] ** 2 - min_h_m**2,
        )
        return max(0.0, lo), min(1.0, hi)
    h_lo, h_hi = _below(
        d[0] ** 2 + d[1] ** 2,
        2.0 * (r0[0] * d[0] + r0[1] * d[1]),
        r0[0] ** 2 + r0[1] ** 2 - min_h_m**2,
    )
    v_lo, v_hi = _below(d[2] ** 2, 2.0 * r0[2] * d[2], r0[2] ** 2 - min_v_m**2)
    return max(0.0, h_lo, v_lo), min(1.0, h_hi, v_hi)


def _intrusions(
    uas: str,
    history: Sequence[tuple[float, float, float, float]],
    airborne: npt.NDArray[np.bool_],
    geofences: Mapping[str, Geofence],
    *,
    frame: LocalFrame,
    t0_s: float,
) -> list[TruthIntrusion]:
    """Records of one vehicle inside an active geofence that applies to it, per geofence;
    each record found inside counts the time to the next record."""
    if not history:
        return []
    h = np.asarray(history, dtype=np.float64)
    east, north = frame.to_local(h[:, 1], h[:, 2])
    dt = np.diff(h[:, 0], append=h[-1, 0])
    out = []
    for g in geofences.values():
        if not g.applies_to(uas):
            continue
        lf = localise(g, frame)
        inside = [
            k
            for k in range(len(h))
            if airborne[k]
            and g.active_at(float(h[k, 0]))
            and inside_fence(lf, float(east[k]), float(north[k]), float(h[k, 3]))
        ]
        if inside:
            out.append(
                TruthIntrusion(
                    uas=uas,
                    geofence=g.id,
                    first_at_s=round(float(h[inside[0], 0]) - t0_s, 3),
                    duration_s=round(float(sum(dt[k] for k in inside)), 3),
                    samples_inside=len(inside),
                )
            )
    return out


def inside_fence(lf: Any, east_m: float, north_m: float, alt_amsl_m: float) -> bool:
    """Is a point inside a localised geofence (altitude band, then cylinder or polygon)?"""
    if not lf.z_lo <= alt_amsl_m <= lf.z_hi:
        return False
    if lf.center is not None:
        return bool(math.hypot(east_m - lf.center[0], north_m - lf.center[1]) <= lf.radius_m)
    inside = points_in_edges(np.array([east_m]), np.array([north_m]), lf.edges)
    return bool(inside[0])


def local_history(
    frame: LocalFrame, history: Sequence[tuple[float, float, float, float]]
) -> FloatArray:
    """(K, 4) rows of t_s, east_m, north_m, alt_amsl_m in true metres."""
    if not history:
        return np.zeros((0, 4))
    h = np.asarray(history, dtype=np.float64)
    east, north = tangent_plane_m(frame.origin_lat_deg, frame.origin_lon_deg, h[:, 1], h[:, 2])
    return np.column_stack((h[:, 0], east, north, h[:, 3]))


_WGS84_A_M = 6378137.0
_WGS84_E2 = 6.69437999014e-3


def tangent_plane_m(
    lat0_deg: float, lon0_deg: float, lat_deg: FloatArray, lon_deg: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(east_m, north_m) in the tangent plane at the origin, through Earth-centred
    coordinates: true metres (no map projection's scale factor), so the truth does not share
    the UTM frame the service computes in."""

    def ecef(lat: FloatArray, lon: FloatArray) -> FloatArray:
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
