"""Joint selection of one alternative per UAS (paper eq. 1):

    minimise  sum_i (alpha * c_i + beta * r_i)
    subject to  the chosen plans are pairwise conflict-free (Monitoring's check)

Exact branch and bound: UAS in order of fewest options first, each UAS's options by ascending
score, a lower bound of the partial sum plus every remaining UAS's cheapest option, and a
memoised pairwise compatibility test. The search visits at most ``max_nodes`` partial
combinations; past that it returns the best complete combination found so far and says it was
truncated (it is then a heuristic answer, recorded as such in the audit).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from gcs_utm.model import Alternative, OperationId


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
