"""Joint selection of one alternative per UAS (paper eq. 1):

    minimise  sum_i (alpha * c_i + beta * r_i)
    subject to  the chosen plans are pairwise conflict-free (Monitoring's check)

Exact branch and bound: UAS in order of fewest options first, each UAS's options by ascending
score, a lower bound of the partial sum plus every remaining UAS's cheapest option, and a
memoised pairwise compatibility test. The search visits at most ``max_nodes`` partial
combinations; past that it returns the best complete combination found so far and says it was
truncated (it is then a heuristic answer, recorded as such in the audit).

:func:`select_by_priority` runs it tier by tier (the priority rule, docs/resolution.md).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from gcs_utm.model import Alternative, FlightPlan, Maneuver, OperationId


@dataclass(frozen=True, slots=True, kw_only=True)
class Selection:
    chosen: dict[OperationId, Alternative]
    total: float
    explored: int
    truncated: bool


def weighted(alt: Alternative, alpha: float, beta: float) -> float:
    return alpha * alt.cost + beta * alt.risk


def select_joint(
    options: Mapping[OperationId, Sequence[Alternative]],
    *,
    alpha: float,
    beta: float,
    compatible: Callable[[Alternative, Alternative], bool],
    max_nodes: int,
) -> Selection | None:
    """The best conflict-free combination, or None when there is none (or none was found
    within ``max_nodes``)."""
    ops = sorted(options, key=lambda k: len(options[k]))
    if any(not options[k] for k in ops):
        return None
    ranked = [sorted(options[k], key=lambda a: weighted(a, alpha, beta)) for k in ops]
    mins = [weighted(r[0], alpha, beta) for r in ranked]
    rest = [sum(mins[i:]) for i in range(len(ops) + 1)]
    cache: dict[tuple[int, int], bool] = {}

    def ok(a: Alternative, b: Alternative) -> bool:
        key = (id(a), id(b)) if id(a) < id(b) else (id(b), id(a))
        if key not in cache:
            cache[key] = compatible(a, b)
        return cache[key]

    best_total = float("inf")
    best: list[Alternative] | None = None
    explored = 0
    truncated = False
    chosen: list[Alternative] = []

    def dfs(i: int, partial: float) -> None:
        nonlocal best_total, best, explored, truncated
        if i == len(ops):
            if partial < best_total:
                best_total = partial
                best = list(chosen)
            return
        for alt in ranked[i]:
            if explored >= max_nodes:
                truncated = True
                return
            explored += 1
            s = partial + weighted(alt, alpha, beta)
            if s + rest[i + 1] >= best_total:
                break  # options are sorted: every later one is worse
            if all(ok(alt, c) for c in chosen):
                chosen.append(alt)
                dfs(i + 1, s)
                chosen.pop()

    dfs(0, 0.0)
    if best is None:
        return None
    return Selection(
        chosen={a.operation_id: a for a in best},
        total=best_total,
        explored=explored,
        truncated=truncated,
    )


STAY_DETAIL = "no conflict-free option: stays on its current plan, which Monitoring flags"
STAY_RISK = 100.0
"""Riskiness of staying on a flagged plan: far above any verified option (one unit of risk
is a closest approach at the minimum), so it is chosen only when nothing else fits."""


def stay(op_id: OperationId, plan: FlightPlan) -> Alternative:
    """The pseudo-option of a UAS without a verified option: it keeps its current plan. It
    lets the others' options be judged against that plan; it never counts as a resolution."""
    return Alternative(
        operation_id=op_id,
        maneuver=Maneuver.KEEP_PLAN,
        plan=plan,
        cost=0.0,
        risk=STAY_RISK,
        detail=STAY_DETAIL,
    )


def is_stay(alt: Alternative) -> bool:
    return alt.detail == STAY_DETAIL


@dataclass(frozen=True, slots=True, kw_only=True)
class TieredSelection:
    """A joint selection and the highest priority that was allowed to move for it."""

    selection: Selection
    moved_up_to_priority: int


def select_by_priority(
    options: Mapping[OperationId, Sequence[Alternative]],
    priorities: Mapping[OperationId, int],
    stays: Mapping[OperationId, Alternative],
    *,
    alpha: float,
    beta: float,
    compatible: Callable[[Alternative, Alternative], bool],
    max_nodes: int,
) -> TieredSelection | None:
    """Joint selection that respects priority: first only the UAS of the lowest priority
    may change plans (every other keeps its plan), then the next priority level too, and so
    on: a higher-priority UAS is moved only when no conflict-free combination exists with it
    on its plan. A UAS without a verified keep-plan option takes its ``stays`` pseudo-option
    when it may not (or cannot) move. A combination in which nothing moves but a UAS stays
    on a flagged plan resolves nothing and is skipped."""
    for level in sorted(set(priorities.values())):
        tier: dict[OperationId, list[Alternative]] = {}
        for op_id, alts in options.items():
            keep = [a for a in alts if a.maneuver is Maneuver.KEEP_PLAN]
            pool = list(alts) if priorities[op_id] <= level else keep
            if not keep and op_id in stays:
                pool.append(stays[op_id])
            tier[op_id] = pool
        sel = select_joint(tier, alpha=alpha, beta=beta, compatible=compatible, max_nodes=max_nodes)
        if sel is None:
            continue
        chosen = sel.chosen.values()
        if any(is_stay(a) for a in chosen) and all(
            a.maneuver is Maneuver.KEEP_PLAN for a in chosen
        ):
            continue
        return TieredSelection(selection=sel, moved_up_to_priority=level)
    return None
