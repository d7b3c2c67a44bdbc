"""A fixed wing entering its loiter circle from the centre swings out on its turn before it
settles (gcs_utm.core.tracking.loiter_entry): predicted on the circle only, a UAS hovering
in that swing was first predicted 0.3 s ahead (enc_4_0160_crossing: out to 142 m from the
end point of an 80 m circle)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from gcs_utm.core.tracking import Tracker
from gcs_utm.core.tracking.loiter_entry import capture_points, capture_turn_radius_m
from gcs_utm.envelope import FIXED_WING_TURN_RADIUS_M
from gcs_utm.model import VehicleKind

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import T0, meas, new_tracker, operation, plan_from_local

SPEED_MPS = 22.7  # the simulated plane of enc_3_0443 on its last leg: a 76 m turn at 35 deg
R_M = FIXED_WING_TURN_RADIUS_M
ALT_M = 100.0


def _tracker(end_t_s: float) -> Tracker:
    """A fixed wing eastbound on north = 0 at SPEED_MPS, its plan ending at (0, 0) at
    ``end_t_s``, measured on its plan's line for 10 s up to T0 + 10."""
    plan = plan_from_local(
        "op1",
        [(-SPEED_MPS * 100.0, 0.0, ALT_M, end_t_s - 100.0), (0.0, 0.0, ALT_M, end_t_s)],
    )
    op = dataclasses.replace(
        operation("op1", plan, sys_id=1, flight_geometry_m=15.0),
        vehicle_kind=VehicleKind.FIXED_WING,
        cruise_speed_mps=SPEED_MPS,
    )
    tr = new_tracker()
    tr.set_operations([op])
    for k in range(21):
        t = T0 + 0.5 * k
        e = SPEED_MPS * (t - end_t_s)
        tr.ingest([meas(e, 0.0, ALT_M, t, eph_m=1.0, vel_ned_mps=(0.0, SPEED_MPS, 0.0))])
    return tr


def test_the_capture_from_the_centre_loops_out_to_two_turn_radii_then_settles() -> None:
    speed = np.array([SPEED_MPS])
    turn_m = float(capture_turn_radius_m(speed)[0])
    assert 70.0 < turn_m < 80.0
    tau = np.arange(0.0, 61.0)[None, :]
    east, north = capture_points(
        center_en=np.zeros((1, 2)),
        radius_m=np.array([R_M]),
        turn_radius_m=np.array([turn_m]),
        clockwise=np.array([True]),
        pos_en=np.zeros((1, 2)),
        course_rad=np.array([0.0]),  # northbound
        speed_mps=speed,
        tau_s=tau,
    )
    dist = np.hypot(east[0], north[0])
    k = int(np.argmax(dist))
    # out to about twice the turn radius, on the right (east) of a northbound last leg
    assert 1.8 * turn_m < dist[k] < 2.1 * turn_m and east[0, k] > 0.5 * dist[k]
    # then on the circle (within the autopilots' spread round it)
    assert np.all(np.abs(dist[40:] - R_M) < 15.0)


def test_a_plan_ending_inside_the_window_is_predicted_on_its_entry_not_at_its_end() -> None:
    tr = _tracker(end_t_s=T0 + 15.0)  # the plan ends 5 s after the prediction's start
    pts = tr.predict(T0 + 10.0).points[0]
    after = pts[pts[:, 3] > T0 + 15.0]
    dist = np.hypot(after[:, 0], after[:, 1])
    k = int(np.argmax(dist))
    # swings out beyond the circle, to the right (south) of the eastbound last leg
    assert dist[k] > 1.7 * R_M and after[k, 1] < -R_M
    assert np.all(np.abs(after[:, 2] - ALT_M) < 1.0)


def test_a_fixed_wing_just_past_its_end_point_is_predicted_on_its_entry() -> None:
    tr = _tracker(end_t_s=T0 + 9.0)  # measured 23 m past the centre: inside the circle
    pts = tr.predict(T0 + 10.0).points[0]
    dist = np.hypot(pts[:, 0], pts[:, 1])
    k = int(np.argmax(dist))
    assert dist[k] > 1.7 * R_M and pts[k, 1] < -R_M
    assert np.all(np.abs(dist[-10:] - R_M) < 15.0)  # and settles on the circle
