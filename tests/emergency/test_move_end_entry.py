"""A fixed wing's moved end point is cleared with the loop it flies entering its circle
(issue 30, a loss created by an accepted plan: enc_5_0320_crossing, UAS3's end moved 80 m,
231 m from UAS4's circling end; entering its circle from the end point it looped out 119 m
towards UAS4, 39.4 m / 14.1 m against 50 / 50 m)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from gcs_utm.core.emergency.circle_entry import entry_loop, entry_reach_m

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_move_end import F1, F2, _scene, loiter, plan_to_local, sc

from gcs_utm.model import ThreatKind


def test_the_entry_loop_goes_out_two_radii_to_the_right_and_back_onto_the_circle() -> None:
    end = np.array([0.0, 0.0, 100.0])
    e, n, t = entry_loop(end, 0.0, 80.0, 20.0, 1.0)  # arriving heading east
    d = np.hypot(e, n)
    far = int(np.argmax(d))
    assert math.isclose(float(d[far]), entry_reach_m(80.0), rel_tol=0.02)
    assert n[far] < -150.0 and abs(e[far]) < 20.0  # to the right of an eastbound arrival
    assert math.isclose(float(d[-1]), 80.0, rel_tol=0.05)  # back on the circle
    assert np.all(np.diff(t) > 0.0)
    steps = np.hypot(np.diff(e), np.diff(n))
    assert float(steps.max()) < 2.0 * 20.0 * 1.0  # no jump: a flyable path, sampled


def test_a_moved_end_point_keeps_the_entry_loop_clear_of_the_other_circle() -> None:
    snap = _scene()  # F1 and F2 circling 150 m apart; F1 (the lower priority) moves
    em = sc.build_manager()
    los = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["F1", "F2"], event_in_s=40.0)
    (rec,) = em.on_threat(los, snap).recommendations
    assert rec.operation_id == F1 and rec.selected is not None and rec.selected.plan is not None
    new_end = plan_to_local(rec.selected.plan, sc.FRAME).xyz()[-1]
    f1, f2 = snap.operations[F1], snap.operations[F2]
    r1, r2 = loiter.loiter_radius_m(f1), loiter.loiter_radius_m(f2)
    h_m, v_m = em.td.pair_minima(f1, f2)
    apart = math.hypot(float(new_end[0]) - 150.0, float(new_end[1]))
    # the loop reaches two of F1's radii from its new end, F2 circles one of its own
    assert apart >= h_m + entry_reach_m(r1) + r2 - 1e-6 or abs(new_end[2] - 100.0) >= v_m
