"""Charged cords: multi-UAS loss-of-separation resolution by iterative repulsive deformation.

Design (from the paper's text; its public code never implemented it): each plan is a *cord*,
the positions it predicts on a common time grid ``t_k = now + k * dt``. Points of two cords at
the same ``t_k`` that are closer than the separation minimum repel each other. Each cord may
move along one *axis* (vertical, or lateral = along the left normal of its own track) in one
*sign*; its displacement is a non-negative profile ``d_k`` along that signed axis.

One iteration: for every pair (i, j) and every violating ``k``, the missing distance (the
*deficit*) is split between the two cords in proportion to their mobility (``1/priority``,
zero for rigid cords); each cord's *demand* at ``k`` is raised to its current displacement plus
its share. The displacement is then the smallest slope-limited profile above the demand:
``d_k = max_j(D_j - s * |k - j|)`` (two running maxima), capped by the ramp from the current
position (``d_k <= s * k``: the UAS is where it is now) and by the altitude limits. The slope
``s`` is the vehicle limit per step (a share of the max climb rate, or a lateral angle at the
cruise speed), so deformations are trapezoids with feasible ramps: no spikes. Iterate until no
pair violates ``minimum * (1 + margin)`` or give up after ``max_iterations``.

Chains (the paper's Figure 9) are resolved because every cord in the problem is pushed by all
its neighbours in the same iteration: moving B away from A into C makes C push back on B and C
move in turn (if C is mobile).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np
import numpy.typing as npt

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.model import FloatArray

IntArray = npt.NDArray[np.intp]


class Axis(Enum):
    """Along what a cord moves: up (sign +1) or down, left (+1, its track's left normal) or
    right, or not at all (a rigid cord)."""

    VERTICAL = "vertical"
    LATERAL = "lateral"
    NONE = "none"


@dataclass(frozen=True, slots=True, kw_only=True)
class Cord:
    """One plan in a cord problem. ``sign`` +1 is up/left, -1 down/right, 0 decided by the
    first repulsion. ``mobility`` 0 makes the cord rigid."""

    plan: LocalPlan
    axis: Axis
    sign: int
    mobility: float
    slope_m_per_step: float
    max_offset_m: float
    min_alt_amsl_m: float
    max_alt_amsl_m: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CordResult:
    displacement_m: FloatArray  # (U, K) >= 0 along each cord's signed axis
    signs: tuple[int, ...]
    iterations: int


@dataclass(frozen=True, slots=True, eq=False)
class Samples:
    """Undeformed cords on the grid: positions (U, K, 3), validity (U, K), normals (U, K, 2)."""

    base: FloatArray
    valid: npt.NDArray[np.bool_]
    normals: FloatArray


def sample_cords(plans: Sequence[LocalPlan], grid_t: FloatArray) -> Samples:
    u, k = len(plans), grid_t.shape[0]
    base = np.zeros((u, k, 3))
    valid = np.zeros((u, k), dtype=bool)
    normals = np.zeros((u, k, 2))
    for i, p in enumerate(plans):
        base[i], valid[i] = p.sample(grid_t)
        normals[i] = left_normals(base[i])
    return Samples(base=base, valid=valid, normals=normals)


@dataclass(frozen=True, slots=True, eq=False)
class Problem:
    """What every scenario on the same cords shares (axes, signs and mobility aside): the
    undeformed samples, the minima, which (i < j, k) pairs both exist, and the separation
    of the undeformed cords with its target (the first iteration of every scenario starts
    from there). Build it with :func:`prepare`."""

    samples: Samples
    minima: FloatArray  # (U, U, 2)
    spherical: bool
    margin_fraction: float
    pairs: npt.NDArray[np.bool_]  # (U, U, K): i < j and both valid at k
    h_min: FloatArray  # (U, U, 1)
    v_min: FloatArray
    inv_h: FloatArray
    inv_v: FloatArray
    sep0: FloatArray  # (U, U, K) normalised separation, undeformed
    target: FloatArray  # (U, U, K) what every scenario must reach


def _separation(
    pos: FloatArray, inv_h: FloatArray, inv_v: FloatArray, *, spherical: bool
) -> FloatArray:
    """(U, U, K) separation of every pair at every step, in units of the pair's minima."""
    dh = np.hypot(pos[:, None, :, 0] - pos[None, :, :, 0], pos[:, None, :, 1] - pos[None, :, :, 1])
    dv = np.abs(pos[:, None, :, 2] - pos[None, :, :, 2])
    return np.asarray(
        np.hypot(dh, dv) * inv_h if spherical else np.maximum(dh * inv_h, dv * inv_v),
        dtype=np.float64,
    )


def prepare(
    plans: Sequence[LocalPlan],
    grid_t: FloatArray,
    minima: FloatArray,
    *,
    spherical: bool,
    margin_fraction: float,
    samples: Samples | None = None,
) -> Problem:
    """The scenario-independent part of a cord problem on ``plans`` (see :class:`Problem`)."""
    if samples is None:
        samples = sample_cords(plans, grid_t)
    u = len(plans)
    valid = samples.valid
    idx = np.arange(u)
    pairs = valid[:, None, :] & valid[None, :, :] & (idx[:, None] < idx[None, :])[:, :, None]
    h_min = minima[:, :, 0][:, :, None]
    v_min = minima[:, :, 1][:, :, None]
    inv_h = 1.0 / np.maximum(h_min, 1e-9)
    inv_v = 1.0 / np.maximum(v_min, 1e-9)
    sep0 = _separation(samples.base, inv_h, inv_v, spherical=spherical)
    scale = 1.0 + margin_fraction
    # Pairs already separated but inside the margin (e.g. a stack at the minimum) only have
    # to stay as they are: demanding the margin there could never be met at the current
    # position (k = 0), where no cord may move.
    target = np.where(sep0 >= 1.0, np.minimum(scale, sep0) - 1e-6, scale)
    return Problem(
        samples=samples,
        minima=minima,
        spherical=spherical,
        margin_fraction=margin_fraction,
        pairs=pairs,
        h_min=h_min,
        v_min=v_min,
        inv_h=inv_h,
        inv_v=inv_v,
        sep0=sep0,
        target=target,
    )


def left_normals(pos: FloatArray) -> FloatArray:
    """(K, 2) unit left normals of the horizontal track through pos (K, 3); a hover keeps the
    previous direction, a cord that never moves points east."""
    nx, ny = left_normals_en(pos[:, 0], pos[:, 1])
    return np.column_stack([nx, ny])


def left_normals_en(e: FloatArray, n: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`left_normals` of the track through (e, n), one array per component."""
    k = e.shape[0]
    de = np.zeros(k)
    dn = np.zeros(k)
    if k > 1:
        de[:-1] = e[1:] - e[:-1]
        dn[:-1] = n[1:] - n[:-1]
        de[-1] = de[-2]
        dn[-1] = dn[-2]
    norm = np.hypot(de, dn)
    good = norm > 1e-6
    if not good.any():
        return np.zeros(k), np.ones(k)
    idx = np.where(good, np.arange(k), 0)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(good))
    idx[:first] = first
    nk = norm[idx]
    return -(dn[idx] / nk), de[idx] / nk


def envelope(demand: FloatArray, slope: float) -> FloatArray:
    """Smallest profile >= demand whose step-to-step change is at most ``slope``."""
    idx = np.arange(demand.shape[0], dtype=np.float64)
    fwd = np.maximum.accumulate(demand + slope * idx) - slope * idx
    rev = fwd[::-1]
    bwd = np.maximum.accumulate(rev + slope * idx) - slope * idx
    return np.asarray(np.maximum(fwd, bwd[::-1]), dtype=np.float64)


def apply(
    base: FloatArray, normals: FloatArray, axis: Axis, sign: int, d: FloatArray
) -> FloatArray:
    out = base.copy()
    if axis is Axis.VERTICAL:
        out[:, 2] += sign * d
    elif axis is Axis.LATERAL:
        out[:, :2] += (sign * d)[:, None] * normals
    return out


def resolve(  # noqa: C901, PLR0912, PLR0915 - the charged-cords iteration of the paper, one loop
    cords: Sequence[Cord],
    grid_t: FloatArray,
    minima: FloatArray,
    *,
    spherical: bool,
    margin_fraction: float,
    max_iterations: int,
    problem: Problem | None = None,
) -> CordResult | None:
    """Deform ``cords`` on ``grid_t`` until every pair holds ``minima[i, j] = (h, v)``
    (times 1 + margin); None when the scenario cannot be resolved. ``problem`` is the
    scenario-independent part (:func:`prepare`) when the caller already has it (several
    scenarios on the same cords, minima and grid)."""
    u = len(cords)
    k = grid_t.shape[0]
    if problem is None:
        problem = prepare(
            [c.plan for c in cords],
            grid_t,
            minima,
            spherical=spherical,
            margin_fraction=margin_fraction,
        )
    base, normals = problem.samples.base, problem.samples.normals
    h_min, v_min, inv_h, inv_v = problem.h_min, problem.v_min, problem.inv_h, problem.inv_v
    signs = [c.sign for c in cords]
    d = np.zeros((u, k))
    demand = np.zeros((u, k))
    ramp = np.arange(k, dtype=np.float64)
    caps = np.zeros((u, k))
    for i, c in enumerate(cords):
        caps[i] = np.minimum(c.slope_m_per_step * ramp, c.max_offset_m)
    # Unit direction of each cord's displacement at every step (U, K, 3): up, the left
    # normal, or nothing; a cord's position is then base + sign * d * direction.
    dirs = np.zeros((u, k, 3))
    for i, c in enumerate(cords):
        if c.axis is Axis.VERTICAL:
            dirs[i, :, 2] = 1.0
        elif c.axis is Axis.LATERAL:
            dirs[i, :, :2] = normals[i]
    # A pair of rigid cords is not this scenario's business (another threat covers it).
    movable = np.array([c.mobility > 0.0 and c.axis is not Axis.NONE for c in cords])
    both = problem.pairs & (movable[:, None] | movable[None, :])[:, :, None]
    scale = 1.0 + margin_fraction
    target = problem.target
    for it in range(max_iterations + 1):
        if it == 0:
            pos, sep = base, problem.sep0  # nothing has moved yet
        else:
            sgn = np.array([sg or 1 for sg in signs], dtype=np.float64)
            pos = base + (sgn[:, None] * d)[:, :, None] * dirs
            sep = _separation(pos, inv_h, inv_v, spherical=spherical)
        viol = both & (sep < target)
        if not viol.any():
            return CordResult(displacement_m=d, signs=tuple(s or 1 for s in signs), iterations=it)
        if it == max_iterations:
            return None
        for i, j in zip(*np.nonzero(viol.any(axis=2)), strict=True):
            ks = np.flatnonzero(viol[i, j])
            mi, mj = cords[i].mobility, cords[j].mobility
            _choose_signs(cords, signs, pos, normals, i, j, ks)
            for c, o, m in ((i, j, mi), (j, i, mj)):
                if m <= 0.0 or cords[c].axis is Axis.NONE:
                    continue
                share = m / (mi + mj) if (cords[o].mobility > 0 and _opposed(cords, c, o)) else 1.0
                rel = pos[c, ks] - pos[o, ks]
                if cords[c].axis is Axis.VERTICAL:
                    along = rel[:, 2]
                    need = v_min[c, o, 0] * scale
                else:
                    along = np.einsum("kj,kj->k", rel[:, :2], normals[c, ks])
                    need = h_min[c, o, 0] * scale
                if spherical:
                    need = h_min[c, o, 0] * scale
                deficit = need - signs[c] * along
                deficit = np.maximum(deficit, 0.0)
                demand[c, ks] = np.maximum(demand[c, ks], d[c, ks] + share * deficit + 0.5)
        before = d.copy()
        before_signs = list(signs)
        for i, c in enumerate(cords):
            if c.axis is Axis.NONE or c.mobility <= 0.0:
                continue
            cap = caps[i]
            if c.axis is Axis.VERTICAL:
                room = (
                    c.max_alt_amsl_m - base[i, :, 2]
                    if (signs[i] or 1) > 0
                    else base[i, :, 2] - c.min_alt_amsl_m
                )
                cap = np.minimum(cap, np.maximum(room, 0.0))
            d[i] = np.minimum(envelope(demand[i], c.slope_m_per_step), cap)
        if signs == before_signs and np.array_equal(d, before):
            # Stuck at the caps: the next iteration would see the same positions, make the
            # same demands and the same profiles, forever. Give up now.
            return None
    return None


def _own_sign(  # noqa: PLR0917 - private helper
    cords: Sequence[Cord], pos: FloatArray, normals: FloatArray, c: int, o: int, ks: IntArray
) -> int:
    """Away from ``o`` over the violating steps. Laterally, when ``o`` is on both sides of
    ``c`` during the violation (the tracks cross), there is no side to move away to: turn
    right, as the rules of the air say (both right also resolves head-on and converging
    traffic: each passes behind the other)."""
    rel = pos[c, ks] - pos[o, ks]
    if cords[c].axis is Axis.VERTICAL:
        mean = float(np.mean(rel[:, 2]))
        return (1 if mean > 0 else -1) if abs(mean) > 1e-3 else (1 if c < o else -1)
    along = np.einsum("kj,kj->k", rel[:, :2], normals[c, ks])
    tol = 1.0  # metres: a side is a side only if clearly so
    if float(along.min()) < -tol and float(along.max()) > tol:
        return -1
    mean = float(np.mean(along))
    return (1 if mean > 0 else -1) if abs(mean) > 1e-3 else -1


def _choose_signs(  # noqa: PLR0917 - private helper
    cords: Sequence[Cord],
    signs: list[int],
    pos: FloatArray,
    normals: FloatArray,
    i: int,
    j: int,
    ks: IntArray,
) -> None:
    """Fix the free signs of a violating pair, once. Two mobile vertical cords split: one up,
    one down. Lateral cords each take their own side (:func:`_own_sign`)."""
    free = [
        c
        for c in (i, j)
        if signs[c] == 0 and cords[c].axis is not Axis.NONE and cords[c].mobility > 0
    ]
    if not free:
        return
    mobile = all(cords[c].axis is Axis.VERTICAL and cords[c].mobility > 0 for c in (i, j))
    if mobile:
        if len(free) == 2:
            signs[i] = _own_sign(cords, pos, normals, i, j, ks)
            signs[j] = -signs[i]
        elif free == [i]:
            signs[i] = -signs[j]
        else:
            signs[j] = -signs[i]
        return
    for c in free:
        signs[c] = _own_sign(cords, pos, normals, c, j if c == i else i, ks)


def _opposed(cords: Sequence[Cord], c: int, o: int) -> bool:
    """Two mobile cords share a deficit only when moving one helps the other, i.e. both use
    the same axis (an up-mover and a left-mover cannot split a vertical deficit)."""
    return cords[c].axis is cords[o].axis


def lateral_slope(speed_mps: float, dt_s: float, angle_deg: float) -> float:
    return speed_mps * dt_s * math.tan(math.radians(angle_deg))
