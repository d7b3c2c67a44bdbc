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


def _two_captures(tau_s: np.ndarray, rows: slice = slice(None)) -> tuple[np.ndarray, ...]:
    """A clockwise capture from the centre and a counter-clockwise one from off it (rows
    ``rows`` of them), at ``tau_s``."""
    speed = np.array([22.7, 16.0])[rows]
    return capture_points(
        center_en=np.array([[0.0, 0.0], [100.0, -50.0]])[rows],
        radius_m=np.array([80.0, 60.0])[rows],
        turn_radius_m=capture_turn_radius_m(speed),
        clockwise=np.array([True, False])[rows],
        pos_en=np.array([[0.0, 0.0], [130.0, -40.0]])[rows],
        course_rad=np.array([0.0, 2.0])[rows],
        speed_mps=speed,
        tau_s=tau_s,
    )


def test_the_capture_keeps_its_figures_to_the_last_bit() -> None:
    # The evaluation is deterministic (docs/evaluation.md): the integration may be made
    # faster, never different. Figures of the model as first written, in hex.
    east, north = _two_captures(np.array([[0.0, 7.3, 20.0, 45.5], [1.0, 12.6, 33.3, 60.0]]))
    want_e = [
        ["0x0.0p+0", "0x1.ded6d87add5a1p+6", "-0x1.52f781faafa28p+4", "-0x1.07ca1d63916c4p+5"],
        [
            "0x1.230a94b94e481p+7",
            "0x1.3a62897641e07p+6",
            "0x1.3e2a5c80524e4p+7",
            "0x1.36cdab34effb2p+7",
        ],
    ]
    want_n = [
        ["0x0.0p+0", "0x1.e2577bd7c6539p+5", "-0x1.6b95bf10a1685p+6", "-0x1.4d8dfb0e51560p+6"],
        [
            "-0x1.5b10ada176647p+5",
            "0x1.34fbe7d238209p+4",
            "-0x1.2becc8cb3e1fdp+4",
            "-0x1.92744fad1e97cp+3",
        ],
    ]
    assert [[float(v).hex() for v in r] for r in east] == want_e
    assert [[float(v).hex() for v in r] for r in north] == want_n


def test_a_capture_is_the_same_alone_or_integrated_with_others() -> None:
    # The tracker integrates all the captures of a prediction in one call: a row's figures
    # must not depend on the others (nor on the longer integration another row needs).
    tau = np.array([[0.0, 3.5, 9.0, 0.0], [2.0, 17.25, 40.0, 58.9]])
    east, north = _two_captures(tau)
    for r in range(2):
        short = tau[r : r + 1, : 3 if r == 0 else 4]
        e1, n1 = _two_captures(short, slice(r, r + 1))
        assert np.array_equal(e1[0], east[r, : short.shape[1]])
        assert np.array_equal(n1[0], north[r, : short.shape[1]])


def test_two_fixed_wings_ending_in_the_window_are_predicted_as_each_alone() -> None:
    # Their captures are integrated together: each must come out as if it were alone.
    t = T0 + 10.0
    both = _planes((0, 1)).predict(t)
    for i in (0, 1):
        alone = _planes((i,)).predict(t)
        pts = both.points[both.track_ids.index(alone.track_ids[0])]
        assert np.array_equal(pts, alone.points[0])
        # swung out past its circle after its end (the capture, not a stop at the end)
        (_, (ee, en), _) = _LEGS[i]
        assert np.hypot(pts[:, 0] - ee, pts[:, 1] - en).max() > 1.7 * R_M


# Eastbound ending at (0, 0) at T0 + 15, northbound ending at (500, 0) at T0 + 30.
_LEGS = (((1.0, 0.0), (0.0, 0.0), T0 + 15.0), ((0.0, 1.0), (500.0, 0.0), T0 + 30.0))


def _planes(which: tuple[int, ...]) -> Tracker:
    """Fixed wings ``which`` of :data:`_LEGS` at SPEED_MPS, measured on their lines for 10 s
    up to T0 + 10."""
    ops = []
    for i in which:
        (ue, un), (ee, en), end_t = _LEGS[i]
        start = (ee - ue * SPEED_MPS * 100.0, en - un * SPEED_MPS * 100.0, ALT_M, end_t - 100.0)
        plan = plan_from_local(f"op{i + 1}", [start, (ee, en, ALT_M, end_t)])
        op = operation(f"op{i + 1}", plan, sys_id=i + 1, flight_geometry_m=15.0)
        kind = VehicleKind.FIXED_WING
        ops.append(dataclasses.replace(op, vehicle_kind=kind, cruise_speed_mps=SPEED_MPS))
    tr = new_tracker()
    tr.set_operations(ops)
    for k in range(21):
        t = T0 + 0.5 * k
        for i in which:
            (ue, un), (ee, en), end_t = _LEGS[i]
            d = SPEED_MPS * (t - end_t)  # m along the leg from its end
            vel = (un * SPEED_MPS, ue * SPEED_MPS, 0.0)  # NED
            tr.ingest(
                [meas(ee + ue * d, en + un * d, ALT_M, t, sys_id=i + 1, eph_m=1.0, vel_ned_mps=vel)]
            )
    return tr
