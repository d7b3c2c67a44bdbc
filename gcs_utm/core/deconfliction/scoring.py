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

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.geometry import LocalFence, LocalPlan
from gcs_utm.model import Closest, FloatArray

SAMPLE_DT_S = 1.0
"""Sampling step of the risk terms: 1 s is below a metre-scale error at UAS speeds."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Neighbour:
    plan: LocalPlan
    h_min_m: float
    v_min_m: float
    name: str = ""
    """The other UAS (for the pilot's wording of the closest separation)."""


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
    closest: Closest | None = None
    """Where ``min_separation_ratio`` is reached, in metres (None: no neighbour in range)."""

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


class _Segments:
    """The segments of a 3D polyline (M >= 2 vertices), prepared once for many point
    queries: start points and direction vectors as (S, 1) columns, squared lengths."""

    __slots__ = ("ax", "ay", "az", "bx", "by", "bz", "ll")

    def __init__(self, vertices: FloatArray) -> None:
        a = vertices[:-1]
        ab = vertices[1:] - a
        self.ax, self.ay, self.az = a[:, 0, None], a[:, 1, None], a[:, 2, None]
        self.bx, self.by, self.bz = ab[:, 0, None], ab[:, 1, None], ab[:, 2, None]
        self.ll = np.maximum(self.bx * self.bx + self.by * self.by + self.bz * self.bz, 1e-12)

    def distances(self, px: FloatArray, py: FloatArray, pz: FloatArray) -> FloatArray:
        """3D distance of each point (N,) to the polyline: (S, N) in one pass, component by
        component (the same operations, in the same order, as :func:`distance_to_polyline`)."""
        qx, qy, qz = px - self.ax, py - self.ay, pz - self.az
        u = np.minimum(np.maximum((qx * self.bx + qy * self.by + qz * self.bz) / self.ll, 0.0), 1.0)
        dx, dy, dz = qx - u * self.bx, qy - u * self.by, qz - u * self.bz
        return np.asarray(np.sqrt((dx * dx + dy * dy + dz * dz).min(axis=0)), dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class Reference:
    """What every alternative of one UAS is scored against in one decision, prepared once:
    the remaining plan ``old`` (from now), the whole ``filed`` plan, the OV radius and the
    other plans for the proximity term. Build it with :func:`reference`."""

    old: LocalPlan
    filed: LocalPlan
    ov_radius_m: float
    neighbours: Sequence[Neighbour]
    old_length_m: float
    old_segments: _Segments | None  # None: fewer than 2 points
    filed_segments: _Segments | None


def reference(
    old: LocalPlan, filed: LocalPlan, ov_radius_m: float, neighbours: Sequence[Neighbour]
) -> Reference:
    return Reference(
        old=old,
        filed=filed,
        ov_radius_m=ov_radius_m,
        neighbours=tuple(neighbours),
        old_length_m=old.length_m(),
        old_segments=_Segments(old.xyz()) if len(old) >= 2 else None,
        filed_segments=_Segments(filed.xyz()) if len(filed) >= 2 else None,
    )


def _prox(x: float, factor: float) -> float:
    # Plain min/max on a Python float: the same value as np.clip, without the array call.
    return float(min(max((factor - x) / (factor - 1.0), 0.0), 1.0))


def sample_times(t0_s: FloatArray, t1_s: FloatArray, counts: npt.NDArray[np.intp]) -> FloatArray:
    """``np.linspace(t0_s[i], t1_s[i], counts[i])`` for every i (counts >= 2), concatenated:
    the same arithmetic as linspace (index times step, plus start; the last is the stop), in
    a few array operations instead of one call per plan."""
    starts = np.zeros(counts.shape[0], dtype=np.intp)
    np.cumsum(counts[:-1], out=starts[1:])
    k = np.arange(int(counts.sum()), dtype=np.float64) - np.repeat(starts, counts)
    step = (t1_s - t0_s) / (counts - 1)
    times = k * np.repeat(step, counts) + np.repeat(t0_s, counts)
    times[starts + counts - 1] = t1_s
    return times


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
    """The score of one new plan (:func:`score_many` with one candidate)."""
    return score_many(
        [new],
        reference(old, filed, ov_radius_m, neighbours),
        fences=fences,
        applies=None,
        priority_weight=priority_weight,
        priority_levels=priority_levels,
        abandons=[abandons],
        spherical=spherical,
        config=config,
    )[0]


def score_many(  # noqa: C901, PLR0912, PLR0915 - every candidate scored in one vectorised pass
    news: Sequence[LocalPlan],
    ref: Reference,
    *,
    fences: Sequence[LocalFence],
    applies: Sequence[npt.NDArray[np.bool_]] | None,
    priority_weight: float,
    priority_levels: int = 0,
    abandons: Sequence[bool],
    spherical: bool,
    config: DeconflictionConfig,
) -> list[Score]:
    """Cost and riskiness of several new plans of one UAS against the same reference, in one
    vectorised pass: every plan is sampled every ``SAMPLE_DT_S`` at most, the samples of all
    plans are concatenated, and every term is computed on the concatenation (per-plan sums
    and extrema over its own slice). Each result equals what the plan alone would get, bit
    for bit (same operations on the same values in the same order). ``applies[i]`` says which
    of ``fences`` count for plan i (None: all)."""
    m = len(news)
    ov = ref.ov_radius_m
    old = ref.old
    # -- samples of every plan, concatenated: plan i owns [s0[i], s0[i] + cnt[i]).
    t0 = np.array([float(p.t[0]) for p in news])
    t1 = np.array([float(p.t[-1]) for p in news])
    cnt = np.maximum(2, ((t1 - t0) / SAMPLE_DT_S).astype(np.intp) + 1)
    s0 = np.zeros(m, dtype=np.intp)
    np.cumsum(cnt[:-1], out=s0[1:])
    times = sample_times(t0, t1, cnt)
    n = times.shape[0]
    px, py, pz = np.empty(n), np.empty(n), np.empty(n)
    for i, p in enumerate(news):
        sl = slice(int(s0[i]), int(s0[i] + cnt[i]))
        if len(p) == 1:
            px[sl], py[sl], pz[sl] = p.e[0], p.n[0], p.z[0]
        else:
            ts = times[sl]
            px[sl] = np.interp(ts, p.t, p.e)
            py[sl] = np.interp(ts, p.t, p.n)
            pz[sl] = np.interp(ts, p.t, p.z)
    # Sampled stretches: entry j joins samples j and j + 1; the entry between two plans
    # (at s0[i] + cnt[i] - 1) is not a stretch and is masked out or sliced away below.
    dx, dy, dz = px[1:] - px[:-1], py[1:] - py[:-1], pz[1:] - pz[:-1]
    seg = np.sqrt(dx * dx + dy * dy + dz * dz)
    mx, my, mz = 0.5 * (px[1:] + px[:-1]), 0.5 * (py[1:] + py[:-1]), 0.5 * (pz[1:] + pz[:-1])
    tmid = 0.5 * (times[1:] + times[:-1])
    real = np.ones(n - 1, dtype=bool)
    real[(s0 + cnt - 1)[:-1]] = False

    # -- every plan's vertices, concatenated: plan i owns [v0[i], v0[i] + len(plan i)).
    vcnt = np.array([len(p) for p in news], dtype=np.intp)
    v0 = np.zeros(m, dtype=np.intp)
    np.cumsum(vcnt[:-1], out=v0[1:])
    vx = np.concatenate([p.e for p in news])
    vy = np.concatenate([p.n for p in news])
    vz = np.concatenate([p.z for p in news])
    ex, ey, ez = vx[1:] - vx[:-1], vy[1:] - vy[:-1], vz[1:] - vz[:-1]
    vseg = np.sqrt(ex * ex + ey * ey + ez * ez)

    # m, 3D: the farthest vertex of each new path from the old path (the new plan's own
    # vertices are where it bends, so a short spike is not missed) ...
    offsets = np.zeros(m)
    if ref.old_segments is not None:
        offsets = np.maximum.reduceat(ref.old_segments.distances(vx, vy, vz), v0)
    elif len(old) == 1:
        ox, oy, oz = vx - old.e[0], vy - old.n[0], vz - old.z[0]
        offsets = np.maximum.reduceat(np.sqrt(ox * ox + oy * oy + oz * oz), v0)
    # ... and the sampled stretches farther than the OV radius from the filed plan.
    far = None
    if ref.filed_segments is not None:
        far = ref.filed_segments.distances(mx, my, mz) > ov

    # -- geofences: the length inside and the closest approach, per plan.
    inside = [0.0] * m
    min_fence = np.full(m, np.inf)
    for f_idx, f in enumerate(fences):
        active = real & f.active_mask(tmid) & (mz >= f.min_alt_amsl_m - ov)
        active &= mz <= f.max_alt_amsl_m + ov
        if applies is not None:
            for i in range(m):
                if not applies[i][f_idx]:
                    active[int(s0[i]) : int(s0[i] + cnt[i] - 1)] = False
        if not active.any():
            continue
        dist = np.full(n - 1, np.inf)
        dist[active] = f.horizontal_distance(mx[active], my[active])
        min_fence = np.minimum(min_fence, np.minimum.reduceat(dist, s0))
        into = dist < 0.0
        for i in range(m):
            sl = slice(int(s0[i]), int(s0[i] + cnt[i] - 1))
            if into[sl].any():
                inside[i] += float(np.sum(seg[sl][into[sl]]))

    # -- the closest normalised separation to every other plan, per plan.
    min_ratio = np.full(m, np.inf)
    closest: list[Closest | None] = [None] * m
    for nb in ref.neighbours:
        other, ok = nb.plan.sample(times)
        if not ok.any():
            continue
        dh = np.hypot(px - other[:, 0], py - other[:, 1])
        dv = np.abs(pz - other[:, 2])
        if spherical:
            ratio = np.hypot(dh, dv) / nb.h_min_m
        else:
            ratio = np.maximum(dh / nb.h_min_m, dv / nb.v_min_m)
        ratio[~ok] = np.inf
        per_plan = np.minimum.reduceat(ratio, s0)
        for j in np.flatnonzero(per_plan < min_ratio).tolist():  # this neighbour is closer
            k = int(s0[j]) + int(np.argmin(ratio[int(s0[j]) : int(s0[j] + cnt[j])]))
            closest[j] = Closest(
                other=nb.name,
                horizontal_m=float(dh[k]),
                vertical_m=float(dv[k]),
                min_horizontal_m=nb.h_min_m,
                min_vertical_m=nb.v_min_m,
                spherical=spherical,
            )
        min_ratio = np.minimum(min_ratio, per_plan)

    factor = config.risk_proximity_factor
    out = []
    for i, new in enumerate(news):
        ve = int(v0[i] + vcnt[i])
        new_len = float(vseg[int(v0[i]) : ve - 1].sum())
        extra_d = max(0.0, new_len - ref.old_length_m)  # m, 3D
        extra_t = max(0.0, float(new.t[-1] - old.t[-1]))  # s
        offset = float(offsets[i])
        cost = priority_weight * (
            extra_d / config.cost_distance_scale_m
            + extra_t / config.cost_time_scale_s
            + offset / config.cost_offset_scale_m
        )
        cost += config.priority_move_cost * max(0, priority_levels)
        if abandons[i]:
            cost += config.abandon_cost
        outside_m = 0.0
        if far is not None:
            sl = slice(int(s0[i]), int(s0[i] + cnt[i] - 1))
            outside_m = float(np.sum(seg[sl][far[sl]]))
        fence_m = float(min_fence[i])
        ratio_i = float(min_ratio[i])
        risk = inside[i] / config.risk_length_scale_m + outside_m / config.risk_outside_ov_scale_m
        if math.isfinite(fence_m):
            risk += _prox(fence_m / max(ov, 1e-6), factor)
        if math.isfinite(ratio_i):
            risk += _prox(ratio_i, factor)
        out.append(
            Score(
                cost=cost,
                risk=risk,
                extra_distance_m=extra_d,
                extra_time_s=extra_t,
                offset_m=offset,
                inside_fences_m=inside[i],
                outside_ov_m=outside_m,
                min_fence_distance_m=fence_m,
                min_separation_ratio=ratio_i,
                closest=closest[i],
            )
        )
    return out


def alternative_terms(sc: Score) -> dict[str, Any]:
    """What an :class:`~gcs_utm.model.Alternative` shows the pilot from its score (keyword
    arguments): extra length and time, the manoeuvre's size, the closest separation (ratio
    and metres) and fence distance (None where nothing is in range)."""
    ratio, fence = sc.min_separation_ratio, sc.min_fence_distance_m
    return {
        "extra_length_m": sc.extra_distance_m,
        "extra_time_s": sc.extra_time_s,
        "offset_m": sc.offset_m,
        "separation_ratio": ratio if math.isfinite(ratio) else None,
        "fence_distance_m": fence if math.isfinite(fence) else None,
        "closest": sc.closest if math.isfinite(ratio) else None,
    }
