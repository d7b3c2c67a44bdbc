"""Strategic check of filed plans: pairwise separation and geofence crossings."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, cylinder, operation, polygon

from gcs_utm.core.monitoring import (
    MonitoringConfig,
    plan_vs_geofences,
    plan_vs_plans,
    strategic_check,
)

CFG = MonitoringConfig()


def test_head_on_plans_conflict_with_exact_times() -> None:
    # A flies east at 10 m/s, B west at 10 m/s on the same line and altitude: closing 20 m/s
    # from 1000 m apart; the 50 m minimum is lost at t = (1000 - 50) / 20 = 47.5 s.
    a = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)])
    b = operation("B", [(1000, 0, 100, 0), (0, 0, 100, 100)])
    rep = strategic_check([a, b], [], FRAME, CFG)
    assert len(rep.conflicts) == 1
    c = rep.conflicts[0]
    assert (c.a, c.b) == ("A", "B")
    assert c.first_loss_t_s == pytest.approx(47.5, abs=1e-3)
    assert c.closest_t_s == pytest.approx(50.0, abs=1e-3)
    assert c.min_distance_m == pytest.approx(0.0, abs=1e-3)


def test_vertical_separation_alone_prevents_loss() -> None:
    # Volumes of 5 m each (sum 10 m) leave the configured 15 m vertical minimum in force.
    a = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)], ov=5)
    b = operation("B", [(1000, 0, 116, 0), (0, 0, 116, 100)], ov=5)  # 16 m above
    assert strategic_check([a, b], [], FRAME, CFG).conflicts == ()
    b2 = operation("B", [(1000, 0, 114, 0), (0, 0, 114, 100)], ov=5)
    rep = strategic_check([a, b2], [], FRAME, CFG)
    assert len(rep.conflicts) == 1
    assert rep.conflicts[0].min_vertical_m == pytest.approx(14.0, abs=1e-3)


def test_minimum_never_below_sum_of_operational_volumes() -> None:
    # Parallel tracks 60 m apart: clear of the 50 m minimum, but volumes of 35 m each need 70.
    a = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)], ov=35)
    b = operation("B", [(0, 60, 100, 0), (1000, 60, 100, 100)], ov=35)
    rep = strategic_check([a, b], [], FRAME, CFG)
    assert len(rep.conflicts) == 1
    assert rep.conflicts[0].first_loss_t_s == pytest.approx(0.0)
    small = strategic_check(
        [
            operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)]),
            operation("B", [(0, 60, 100, 0), (1000, 60, 100, 100)]),
        ],
        [],
        FRAME,
        CFG,
    )
    assert small.conflicts == ()


def test_same_path_different_times_is_not_a_conflict() -> None:
    a = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)])
    b = operation("B", [(0, 0, 100, 200), (1000, 0, 100, 300)])
    assert strategic_check([a, b], [], FRAME, CFG).conflicts == ()


def test_crossing_between_samples_found_with_coarse_step() -> None:
    # Fast crossing at right angles at t = 5.5 s, between integer samples and with step 10 s.
    a = operation("A", [(-550, 0, 100, 0), (550, 0, 100, 11)])
    b = operation("B", [(0, -550, 100, 0), (0, 550, 100, 11)])
    rep = strategic_check([a, b], [], FRAME, CFG, step_s=10.0)
    assert len(rep.conflicts) == 1
    assert rep.conflicts[0].closest_t_s == pytest.approx(5.5, abs=1e-3)


def test_sphere_mode_uses_single_safety_distance() -> None:
    cfg = MonitoringConfig(separation_mode="sphere", safety_distance_m=30.0)
    a = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)])
    b = operation("B", [(0, 20, 120, 0), (1000, 20, 120, 100)])  # 3D distance 28.3 m
    assert len(strategic_check([a, b], [], FRAME, cfg).conflicts) == 1
    b2 = operation("B", [(0, 25, 120, 0), (1000, 25, 120, 100)])  # 32.0 m
    assert strategic_check([a, b2], [], FRAME, cfg).conflicts == ()


def test_geofence_crossing_in_space_and_time() -> None:
    op = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)], ov=10)
    square = polygon("sq", [(400, -50), (600, -50), (600, 50), (400, 50)])
    rep = strategic_check([op], [square], FRAME, CFG)
    assert len(rep.crossings) == 1
    # Enters the fence grown by the 10 m volume at x = 390 m -> t = 39 s.
    assert rep.crossings[0].entry_t_s == pytest.approx(39.0, abs=0.05)
    # Fence active only after the UAS has passed: no crossing.
    late = polygon("late", [(400, -50), (600, -50), (600, 50), (400, 50)], start=70.0)
    assert plan_vs_geofences(op.plan, op, [late], FRAME, CFG) == []
    # Fence that activates while the UAS is inside: entry at activation.
    mid = polygon("mid", [(400, -50), (600, -50), (600, 50), (400, 50)], start=50.0)
    (x,) = plan_vs_geofences(op.plan, op, [mid], FRAME, CFG)
    assert x.entry_t_s == pytest.approx(50.0, abs=1e-6)


def test_geofence_altitude_band_and_volume_margin() -> None:
    op = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)], ov=10)
    above = cylinder("c", (500, 0), 50, zlo=111, zhi=200)  # 11 m above: clear of the 10 m volume
    assert plan_vs_geofences(op.plan, op, [above], FRAME, CFG) == []
    near = cylinder("c", (500, 0), 50, zlo=109, zhi=200)
    assert len(plan_vs_geofences(op.plan, op, [near], FRAME, CFG)) == 1
    # Passes 58 m from the centre of a 50 m cylinder: 8 m < 10 m volume -> crossing.
    side = cylinder("s", (500, 58), 50)
    (x,) = plan_vs_geofences(op.plan, op, [side], FRAME, CFG)
    assert x.entry_t_s == pytest.approx(50.0 - math.sqrt(60**2 - 58**2) / 10.0, abs=1e-3)
    far = cylinder("f", (500, 61), 50)
    assert plan_vs_geofences(op.plan, op, [far], FRAME, CFG) == []


def test_concave_u_shape_plan_through_the_notch_is_clear() -> None:
    # A U open to the north; the plan flies north-south through the notch centre.
    u = polygon(
        "U",
        [(0, 0), (300, 0), (300, 300), (200, 300), (200, 100), (100, 100), (100, 300), (0, 300)],
    )
    op = operation("A", [(150, 400, 100, 0), (150, 150, 100, 25)], ov=10)
    assert plan_vs_geofences(op.plan, op, [u], FRAME, CFG) == []
    deeper = operation("A", [(150, 400, 100, 0), (150, 50, 100, 35)], ov=10)
    (x,) = plan_vs_geofences(deeper.plan, deeper, [u], FRAME, CFG)
    assert x.entry_t_s == pytest.approx(29.0, abs=0.05)  # reaches y = 110 at t = 29 s


def test_plan_vs_plans_for_a_candidate_plan() -> None:
    a = operation("A", [(0, 0, 100, 0), (1000, 0, 100, 100)])
    b = operation("B", [(1000, 0, 100, 0), (0, 0, 100, 100)])
    cand = operation("A", [(0, 0, 100, 0), (1000, 0, 160, 100)]).plan
    assert len(plan_vs_plans(a.plan, a, [a, b], FRAME, CFG)) == 1
    # Climbing to 160 m: while horizontally within 50 m (t in 47.5..52.5 s) A is 28.5-31.5 m
    # above B, clear of the 20 m vertical minimum (the sum of the two 10 m volumes).
    assert plan_vs_plans(cand, a, [a, b], FRAME, CFG) == []


def test_degenerate_plans_do_not_crash() -> None:
    hover = operation("H", [(0, 0, 100, 0)])
    twin = operation("T", [(0, 0, 100, 0), (0, 0, 100, 0), (0, 0, 100, 10)])
    rep = strategic_check([hover, twin], [], FRAME, CFG)
    assert len(rep.conflicts) == 1
    assert rep.conflicts[0].min_distance_m == 0.0
    assert strategic_check([], [], FRAME, CFG).conflicts == ()
    assert strategic_check([hover], [], FRAME, CFG).conflicts == ()
