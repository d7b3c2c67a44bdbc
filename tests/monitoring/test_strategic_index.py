"""The strategic check on the space-time index against the every-pair reference
(``strategic_oracle``): same conflicts (every figure, bit for bit, same order), same
geofence crossings, for all pairs and for one plan against the filed ones."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, cylinder, operation, polygon
from strategic_oracle import plan_vs_plans_allpairs, strategic_check_allpairs

from gcs_utm.core.monitoring import MonitoringConfig, plan_vs_plans, strategic_check
from gcs_utm.core.monitoring.plan_index import PlanIndex, window_boxes
from gcs_utm.core.monitoring.strategic import FiledPlans, plan_local, plans_local
from gcs_utm.model import Operation

T0 = 1.7e9  # POSIX seconds: plans at realistic times (window numbers are floor(t / window))


def _airspace(seed: int, n: int, box_m: float) -> list[Operation]:
    """n random plans in a box: 1-5 waypoints, some hovering (repeated positions or times),
    some with large volumes, crossing paths and altitudes within a few minima."""
    rng = np.random.default_rng(seed)
    ops = []
    for i in range(n):
        k = int(rng.integers(1, 6))
        t = T0 + float(rng.uniform(0, 120)) + np.cumsum(rng.choice([0.0, 3.0, 17.5, 40.0], k))
        e = rng.uniform(0, box_m, k)
        nn = rng.uniform(0, box_m, k)
        z = rng.choice([100.0, 108.0, 115.0, 140.0], k)
        if rng.random() < 0.2:  # hover: the same position throughout
            e[:] = e[0]
            nn[:] = nn[0]
        pts = list(zip(e.tolist(), nn.tolist(), z.tolist(), t.tolist(), strict=True))
        ov = float(rng.choice([5.0, 10.0, 40.0]))
        ops.append(operation(f"U{i}", pts, ov=ov))
    return ops


CONFIGS = [
    MonitoringConfig(),
    MonitoringConfig(separation_mode="sphere", safety_distance_m=60.0),
    MonitoringConfig(separation_horizontal_m=120.0, separation_vertical_m=30.0, grid_dt_s=0.0),
    MonitoringConfig(grid_dx_m=1.0, grid_dy_m=1.0, grid_dz_m=1.0, grid_dt_s=45.0),
]


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(0, 28),
    box_m=st.sampled_from([150.0, 600.0, 3000.0]),
    cfg=st.sampled_from(CONFIGS),
    step_s=st.sampled_from([1.0, 2.5, 7.0]),
)
def test_all_pairs_on_the_index_equal_every_pair(
    seed: int, n: int, box_m: float, cfg: MonitoringConfig, step_s: float
) -> None:
    ops = _airspace(seed, n, box_m)
    fences = [
        cylinder("C", (box_m / 2, box_m / 2), box_m / 5, 95.0, 110.0, start=T0 + 30),
        polygon("P", [(0, 0), (box_m / 3, 0), (box_m / 3, box_m), (0, box_m)], end=T0 + 60),
    ]
    fast = strategic_check(ops, fences, FRAME, cfg, step_s=step_s)
    ref = strategic_check_allpairs(ops, fences, FRAME, cfg, step_s=step_s)
    assert fast == ref


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 24),
    cfg=st.sampled_from(CONFIGS),
    step_s=st.sampled_from([1.0, 4.0]),
)
def test_one_plan_against_the_filed_equals_every_pair(
    seed: int, n: int, cfg: MonitoringConfig, step_s: float
) -> None:
    ops = _airspace(seed, n, 500.0)
    rng = np.random.default_rng(seed)
    filed = FiledPlans(FRAME, cfg, step_s=step_s)
    present: list[Operation] = []
    # File one at a time (the pending part and its merges), withdraw some, re-file some.
    for op in ops:
        assert filed.check(op.plan, op) == plan_vs_plans_allpairs(
            op.plan, op, present, FRAME, cfg, step_s=step_s
        )
        filed.add(op)
        present.append(op)
        if rng.random() < 0.25:
            gone = present.pop(int(rng.integers(0, len(present))))
            assert filed.remove(gone.id)
    new = _airspace(seed + 1, 1, 500.0)[0]
    assert filed.check(new.plan, new) == plan_vs_plans_allpairs(
        new.plan, new, present, FRAME, cfg, step_s=step_s
    )
    assert plan_vs_plans(new.plan, new, ops, FRAME, cfg, step_s=step_s) == (
        plan_vs_plans_allpairs(new.plan, new, ops, FRAME, cfg, step_s=step_s)
    )
    assert len(filed) == len(present)


def test_the_index_finds_conflicts_and_skips_distant_plans() -> None:
    # Head-on pair in the same minutes, a third far away, a fourth on the same line later.
    a = operation("A", [(0, 0, 100, T0), (1000, 0, 100, T0 + 100)])
    b = operation("B", [(1000, 0, 100, T0), (0, 0, 100, T0 + 100)])
    far = operation("F", [(9000, 9000, 100, T0), (9900, 9000, 100, T0 + 100)])
    later = operation("L", [(1000, 0, 100, T0 + 400), (0, 0, 100, T0 + 500)])
    cfg = MonitoringConfig()
    filed = FiledPlans(FRAME, cfg)
    for op in (b, far, later):
        filed.add(op)
    (c,) = filed.check(a.plan, a)
    assert (c.a, c.b) == ("A", "B")
    assert c.first_loss_t_s == pytest.approx(T0 + 47.5, abs=1e-3)
    index = PlanIndex(10.0)
    grow = np.full(3, 25.0)
    for op in (b, far, later):
        index.add(op.id, plan_local(op.plan, FRAME), grow)
    assert index.candidates(plan_local(a.plan, FRAME), grow) == ["B"]
    assert index.remove("B") and not index.remove("B")
    assert index.candidates(plan_local(a.plan, FRAME), grow) == []


def test_window_boxes_cover_every_position() -> None:
    ops = _airspace(3, 40, 2000.0)
    local = plans_local([op.plan for op in ops], FRAME)
    for op, pts in zip(ops, local, strict=True):
        assert np.array_equal(pts, plan_local(op.plan, FRAME))  # batch conversion: same numbers
    wb = window_boxes(local, np.zeros((len(ops), 3)), 10.0)
    for i, pts in enumerate(local):
        t = np.linspace(pts[0, 3], pts[-1, 3], 500)
        pos = np.column_stack([np.interp(t, pts[:, 3], pts[:, k]) for k in range(3)])
        for ti, p in zip(t, pos, strict=True):
            sel = (wb.plan == i) & (wb.window == int(np.floor(ti / 10.0)))
            assert sel.sum() == 1
            assert np.all(wb.lo[sel][0] <= p + 1e-6) and np.all(p - 1e-6 <= wb.hi[sel][0])
