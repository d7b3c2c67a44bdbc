"""The separation an option of a joint decision keeps from the other UAS's chosen plans, in
metres, for the pilot's words (:mod:`.wording`).

TD scores each option against the plans of UAS *outside* the conflict; the UAS of the
conflict itself move too, and which of their options is flown is decided by the joint
selection. So the separation a pilot is told about is computed here, once the selection is
known: each shown option against the other chosen plans, sampled every second over the time
both plans are flown, against the pair's effective minima (what Monitoring calls a loss). The
closer of that and TD's own closest (other traffic) is what the option keeps.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.core.deconfliction.scoring import SAMPLE_DT_S
from gcs_utm.model import Alternative, Closest, Operation, OperationId

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction.td import TacticalDeconfliction


def _ratio(c: Closest) -> float:
    if c.spherical:
        return math.hypot(c.horizontal_m, c.vertical_m) / max(c.min_horizontal_m, 1e-9)
    return max(
        c.horizontal_m / max(c.min_horizontal_m, 1e-9), c.vertical_m / max(c.min_vertical_m, 1e-9)
    )


def closest_between(
    td: TacticalDeconfliction, a: Alternative, b: Alternative, ov_a_m: float, ov_b_m: float
) -> Closest | None:
    """The closest separation (by the minima's ratio) of ``a``'s plan from ``b``'s while
    both are flown; None when either has no plan or they never overlap in time."""
    if a.plan is None or b.plan is None:
        return None
    pa, pb = td.local_plan(a.plan), td.local_plan(b.plan)
    t0, t1 = max(pa.t[0], pb.t[0]), min(pa.t[-1], pb.t[-1])
    if t1 < t0:
        return None
    times = np.append(np.arange(t0, t1, SAMPLE_DT_S), t1)
    xa, _ = pa.sample(times)
    xb, _ = pb.sample(times)
    dh = np.hypot(xa[:, 0] - xb[:, 0], xa[:, 1] - xb[:, 1])
    dv = np.abs(xa[:, 2] - xb[:, 2])
    h_min, v_min = td.monitoring.effective_minima(ov_a_m, ov_b_m)
    spherical = td.monitoring.spherical
    ratio = np.hypot(dh, dv) / h_min if spherical else np.maximum(dh / h_min, dv / v_min)
    k = int(np.argmin(ratio))
    return Closest(
        other=str(b.operation_id),
        horizontal_m=float(dh[k]),
        vertical_m=float(dv[k]),
        min_horizontal_m=h_min,
        min_vertical_m=v_min,
        spherical=spherical,
    )


def with_clearance(
    td: TacticalDeconfliction,
    operations: Mapping[OperationId, Operation],
    others: Sequence[Alternative],
    alt: Alternative,
) -> Alternative:
    """``alt`` with ``closest`` / ``separation_ratio`` the closest of TD's (other traffic)
    and of the other chosen options ``others`` (the UAS of the same decision)."""
    best, best_ratio = alt.closest, alt.separation_ratio
    ov = {k: op.operational_volume_m for k, op in operations.items()}
    for other in others:
        got = closest_between(
            td, alt, other, ov.get(alt.operation_id, 0.0), ov.get(other.operation_id, 0.0)
        )
        if got is not None and (best_ratio is None or _ratio(got) < best_ratio):
            best, best_ratio = got, _ratio(got)
    if best is alt.closest:
        return alt
    return replace(alt, closest=best, separation_ratio=best_ratio)
