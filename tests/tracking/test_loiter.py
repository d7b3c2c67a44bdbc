"""A fixed wing that has finished its plan is predicted on its loiter circle around the last
waypoint (gcs_utm.core.tracking.loiter), not on the tangent of that circle."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from gcs_utm.core.tracking import Tracker
from gcs_utm.envelope import FIXED_WING_TURN_RADIUS_M
from gcs_utm.model import VehicleKind

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import (
    T0,
    meas,
    new_tracker,
    operation,
    plan_from_local,
)

SPEED_MPS = 18.0
R_M = FIXED_WING_TURN_RADIUS_M
ALT_M = 100.0


def _tracker(
    kind: VehicleKind, *, clockwise: bool = True, offset_m: float = 0.0, end_t_s: float = T0
) -> tuple[Tracker, float]:
    """A UAS whose plan ends at (0, 0) at ``end_t_s`` (from (-1000, 0), 100 s before),
    measured for 10 s from T0 on a circle of radius R_M + ``offset_m`` around that point
    (clockwise, starting north of it), with its NED velocity. Returns the tracker and the
    bearing (rad, from north) of the last measurement."""
    plan = plan_from_local(
        "op1", [(-1000.0, 0.0, ALT_M, end_t_s - 100.0), (0.0, 0.0, ALT_M, end_t_s)]
    )
    op = dataclasses.replace(
        operation("op1", plan, sys_id=1, flight_geometry_m=15.0),
        vehicle_kind=kind,
        cruise_speed_mps=SPEED_MPS,
    )
    tr = new_tracker()
    tr.set_operations([op])
    r = R_M + offset_m
    turn = 1.0 if clockwise else -1.0
    bearing = 0.0
    for k in range(21):
        t = 0.5 * k
        bearing = turn * SPEED_MPS / r * t
        e, n = r * math.sin(bearing), r * math.cos(bearing)
        v_e, v_n = turn * SPEED_MPS * math.cos(bearing), -turn * SPEED_MPS * math.sin(bearing)
        tr.ingest([meas(e, n, ALT_M, T0 + t, eph_m=1.0, vel_ned_mps=(v_n, v_e, 0.0))])
    return tr, bearing


def _polar(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from (0, 0) and bearing (unwrapped) of predicted points (K, 4)."""
    return np.hypot(points[:, 0], points[:, 1]), np.unwrap(np.arctan2(points[:, 0], points[:, 1]))


@pytest.mark.parametrize("clockwise", [True, False])
def test_a_fixed_wing_after_its_plan_is_predicted_on_its_loiter_circle(clockwise: bool) -> None:
    tr, bearing = _tracker(VehicleKind.FIXED_WING, clockwise=clockwise)
    pred = tr.predict(T0 + 10.0)
    dist, phase = _polar(pred.points[0])
    # Every point of the 60 s horizon lies on the circle (a tangent line leaves it: 1 km out).
    assert np.all(np.abs(dist - R_M) < 3.0)
    assert np.all(np.abs(pred.points[0, :, 2] - ALT_M) < 1.0)
    # ...and goes round it the way the aircraft turns, at its speed.
    turn = 1.0 if clockwise else -1.0
    expected = bearing + turn * SPEED_MPS / R_M * np.arange(len(phase)) * tr.config.step_s
    np.testing.assert_allclose(phase, expected, atol=0.1)


def test_an_offset_from_the_circle_decays_onto_it() -> None:
    tr, _ = _tracker(VehicleKind.FIXED_WING, offset_m=40.0)
    pred = tr.predict(T0 + 10.0)
    dist, _ = _polar(pred.points[0])
    assert dist[0] == pytest.approx(R_M + 40.0, abs=3.0)  # starts where the track is
    assert abs(dist[-1] - R_M) < 1.0  # ends on the loiter radius
    assert np.all(np.diff(dist) <= 1e-9)


def test_a_multirotor_or_a_fixed_wing_far_away_is_not_put_on_a_circle() -> None:
    # A multirotor stops at its last waypoint: circling measurements are extrapolated.
    mr, _ = _tracker(VehicleKind.MULTIROTOR)
    dist, _ = _polar(mr.predict(T0 + 10.0).points[0])
    assert dist[-1] > 5 * R_M
    # A fixed wing more than two loiter radii away has been sent elsewhere.
    far, _ = _tracker(VehicleKind.FIXED_WING, offset_m=R_M * 1.5)
    dist, _ = _polar(far.predict(T0 + 10.0).points[0])
    assert dist[-1] > 5 * R_M


def test_a_fixed_wing_before_its_plan_end_is_not_put_on_a_circle() -> None:
    # The same measurements while the plan still runs (it ends 1000 s later): not loitering.
    tr, _ = _tracker(VehicleKind.FIXED_WING, end_t_s=T0 + 1000.0)
    dist, _ = _polar(tr.predict(T0 + 10.0).points[0])
    assert dist[-1] > 5 * R_M
