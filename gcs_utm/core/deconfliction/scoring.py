"""Cost and riskiness of an alternative (paper §4.5), made unit-free so they can be summed.

For a new plan P' replacing the remaining plan P of operation i (both from now on):

    cost = w_prio * ( max(0, L(P') - L(P)) / cost_distance_scale_m
                    + max(0, T_end(P') - T_end(P)) / cost_time_scale_s
                    + max_t dist3(P'(t), path P) / cost_offset_scale_m )
           + abandon_cost * [P' abandons the mission]
           + priority_move_cost * (priority_i - lowest priority in the conflict)
    w_prio = 1 + priority_cost_weight * (priority_i - lowest priority in the conflict)

L is the 3D (Euclidean) path length, vertical legs included. The offset term is the farthest
the new path gets from the old one (3D): a deformation that cuts a corner of the plan (a
descent under a conflict that shortens the plan's own climb) may fly no extra distance at all,
yet it does leave the plan, so every maneuver that deviates has a positive cost. The
``priority_move_cost`` term is a fixed price for changing the plan of a UAS of higher priority
than the lowest in the problem at all: it moves only when that buys more than the price (a
nudge of the high-priority UAS inside its own volume must not beat a real maneuver of the
low-priority one, paper use case 1). Keeping the plan costs 0.

    risk = inside_m / risk_length_scale_m            (length inside active geofences)
         + outside_ov_m / risk_outside_ov_scale_m    (length farther than the OV radius, in
                                                       3D as Monitoring measures conformance,
                                                       from the whole filed plan, flown part too)
         + prox(d_fence / OV radius)                 (closest approach to an active geofence)
         + prox(s_uas)                               (closest normalised separation to others)
    prox(x) = clip((F - x) / (F - 1), 0, 1), F = risk_proximity_factor

``s_uas`` is min over time of max(h / h_min, v / v_min) (or 3D / minimum in sphere mode):
1 at the separation minimum. Every term is dimensionless: a unit of cost is the configured
scale of extra distance or time, a unit of risk is the scale length in forbidden airspace or a
closest approach at the minimum distance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.geometry import LocalFence, LocalPlan
from gcs_utm.model import FloatArray

SAMPLE_DT_S = 1.0
"""Sampling step of the risk terms: 1 s is below a metre-scale error at UAS speeds."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Neighbour:
    plan: LocalPlan
    h_min_m: float
    v_min_m: float


@dataclass(frozen=True, slots=True, kw_only=True)
class Score:
    cost: float
    risk: float
    extra_distance_m: float
    extra_time_s: float
    offset_m: float
    inside_fences_m: float
    outside_ov_m: float
    min_fence_distance_m: float
    min_separation_ratio: float

    def as_dict(self) -> dict[str, float]:
        return {
            "cost": round(self.cost, 6),
            "risk": round(self.risk, 6),
            "extra_distance_m": round(self.extra_distance_m, 3),
            "extra_time_s": round(self.extra_time_s, 3),
            "offset_m": round(self.offset_m, 3),
            "inside_fences_m": round(self.inside_fences_m, 3),
            "outside_ov_m": round(self.outside_ov_m, 3),
            "min_fence_distance_m": round(self.min_fence_distance_m, 3),
            "min_separation_ratio": round(self.min_separation_ratio, 4),
        }


def distance_to_polyline(points: FloatArray, vertices: FloatArray) -> FloatArray:
    """Distance of each point (N, D) to the polyline through ``vertices`` (M, D), in as many
    dimensions as given (2: horizontal, 3: 3D), vectorised over points x segments (plans have
    few segments)."""
    a = vertices[:-1]
    ab = vertices[1:] - a  # (S, 2)
    ll = np.maximum(np.einsum("sj,sj->s", ab, ab), 1e-12)
    ap = points[:, None, :] - a[None, :, :]  # (N, S, D)
    u = np.clip(np.einsum("nsj,sj->ns", ap, ab) / ll, 0.0, 1.0)
    d = ap - u[:, :, None] * ab[None, :, :]
    return np.asarray(np.sqrt(np.einsum("nsj,nsj->ns", d, d).min(axis=1)), dtype=np.float64)


def _segment_distances(points: FloatArray, polylines: Sequence[FloatArray]) -> list[FloatArray]:
    """For each polyline (M_i, D) with M_i >= 2, the distance of each point (N, D) to it: one
    vectorised pass over the segments of all polylines together."""
    starts = np.concatenate([v[:-1] for v in polylines])
    ab = np.concatenate([v[1:] - v[:-1] for v in polylines])  # (S, D)
    ll = np.maximum((ab * ab).sum(axis=1), 1e-12)
    ap = points[:, None, :] - starts[None, :, :]  # (N, S, D)
    u = np.minimum(np.maximum((ap * ab).sum(axis=2) / ll, 0.0), 1.0)
    d = ap - u[:, :, None] * ab[None, :, :]
    d2 = (d * d).sum(axis=2)
    out = []
    k = 0
    for v in polylines:
        m = len(v) - 1
        out.append(np.sqrt(d2[:, k : k + m].min(axis=1)))
        k += m
    return out


def _prox(x: float, factor: float) -> float:
    # Plain min/max on a Python float: the same value as np.clip, without the array call.
    return float(min(max((factor - x) / (factor - 1.0), 0.0), 1.0))


def score(
    new: LocalPlan,
    old: LocalPlan,
    *,
    filed: LocalPlan,
    ov_radius_m: float,
    fences: Sequence[LocalFence],
    neighbours: Sequence[Neighbour],
    priority_weight: float,
    priority_levels: int = 0,
    abandons: bool,
    spherical: bool,
    config: DeconflictionConfig,
) -> Score:
    new_xyz = new.xyz()
    new_len = float(np.sqrt(((new_xyz[1:] - new_xyz[:-1]) ** 2).sum(axis=1)).sum())
    extra_d = max(0.0, new_len - old.length_m())  # m, 3D
    extra_t = max(0.0, float(new.t[-1] - old.t[-1]))  # s

    span = float(new.t[-1] - new.t[0])
    steps = max(2, int(span / SAMPLE_DT_S) + 1)
    times = np.linspace(float(new.t[0]), float(new.t[-1]), steps)
    pos, _ = new.sample(times)
    seg = np.sqrt(((pos[1:] - pos[:-1]) ** 2).sum(axis=1))
    mid = 0.5 * (pos[1:] + pos[:-1])
    tmid = 0.5 * (times[1:] + times[:-1])

    # m, 3D: the farthest point of the new path from the old path (the new plan's own
    # vertices are added to the sampled midpoints so a short spike is not missed), and
    # the distance of every sampled stretch from the filed plan (outside the OV). One pass.
    nm = mid.shape[0]
    probe = np.concatenate([mid, new_xyz])
    lines = [v for v in (old.xyz(), filed.xyz()) if len(v) >= 2]
    dists = _segment_distances(probe, lines) if lines else []
    offset = 0.0
    if len(old) >= 2:
        offset = float(dists[0][nm:].max())
    elif len(old) == 1:
        offset = float(np.sqrt(((probe[nm:] - old.xyz()[0]) ** 2).sum(axis=1)).max())
    cost = priority_weight * (
        extra_d / config.cost_distance_scale_m
        + extra_t / config.cost_time_scale_s
        + offset / config.cost_offset_scale_m
    )
    cost += config.priority_move_cost * max(0, priority_levels)
    if abandons:
        cost += config.abandon_cost

    inside_m = 0.0
    min_fence = float("inf")
    for f in fences:
        active = np.asarray(f.active_mask(tmid), dtype=bool) & (
            mid[:, 2] >= f.min_alt_amsl_m - ov_radius_m
        )
        active &= mid[:, 2] <= f.max_alt_amsl_m + ov_radius_m
        if not active.any():
            continue
        dist = f.horizontal_distance(mid[active, 0], mid[active, 1])
        inside_m += float(np.sum(seg[active][dist < 0.0]))
        min_fence = min(min_fence, float(dist.min()))

    outside_m = 0.0
    if len(filed) >= 2:
        dist_plan = dists[-1][:nm]
        outside_m = float(np.sum(seg[dist_plan > ov_radius_m]))

    min_ratio = float("inf")
    for nb in neighbours:
        other, ok = nb.plan.sample(times)
        if not ok.any():
            continue
        dh = np.hypot(pos[ok, 0] - other[ok, 0], pos[ok, 1] - other[ok, 1])
        dv = np.abs(pos[ok, 2] - other[ok, 2])
        if spherical:
            ratio = np.hypot(dh, dv) / nb.h_min_m
        else:
            ratio = np.maximum(dh / nb.h_min_m, dv / nb.v_min_m)
        min_ratio = min(min_ratio, float(ratio.min()))

    factor = config.risk_proximity_factor
    risk = inside_m / config.risk_length_scale_m + outside_m / config.risk_outside_ov_scale_m
    if np.isfinite(min_fence):
        risk += _prox(min_fence / max(ov_radius_m, 1e-6), factor)
    if np.isfinite(min_ratio):
        risk += _prox(min_ratio, factor)
    return Score(
        cost=cost,
        risk=risk,
        extra_distance_m=extra_d,
        extra_time_s=extra_t,
        offset_m=offset,
        inside_fences_m=inside_m,
        outside_ov_m=outside_m,
        min_fence_distance_m=min_fence,
        min_separation_ratio=min_ratio,
    )
