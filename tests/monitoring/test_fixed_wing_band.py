"""A fixed wing conforms where it really flies (issue 31.4): inside a turn on its turn radius
(real ArduPlane ran 10-13 m inside a 90 deg corner, beyond its 10 m flight geometry) and
climbing first to a higher waypoint (11.6 m above a straight climb on a 1600 m leg); outside
the corner, inside its arc, above its steepest climb, or as a multirotor it is still flagged."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, operation
from test_monitor import _snapshot

from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.monitoring.checks import pack_plans
from gcs_utm.core.monitoring.fixed_wing_band import band_distance
from gcs_utm.envelope import FIXED_WING_TURN_RADIUS_M, turn_radius_m
from gcs_utm.model import Operation, PerformanceEnvelope, ThreatKind, VehicleKind

# ArduPlane's SITL plane: AIRSPEED_MIN 10, AIRSPEED_MAX 30, TECS_CLMB_MAX 5 m/s
ENVELOPE = PerformanceEnvelope(
    climb_rate_mps=5.0,
    descent_rate_mps=3.0,
    min_speed_mps=10.0,
    max_speed_mps=30.0,
    turn_radius_m=80.0,
    can_hover=False,
)
CONFORMANCE = (ThreatKind.UAS_IN_CV, ThreatKind.UAS_OUT_OV)


def _as(op: Operation, kind: VehicleKind) -> Operation:
    env = ENVELOPE if kind is VehicleKind.FIXED_WING else None
    return dataclasses.replace(op, vehicle_kind=kind, envelope=env)


def _kinds(op: Operation, t: float, at: tuple[float, float, float]) -> list[ThreatKind]:
    mon = Monitor(FRAME, MonitoringConfig())
    snap = _snapshot(t, {"P": (at, (22.0, 0.0, 0.0))}, [op])
    return [x.kind for x in mon.cycle(snap) if x.kind in CONFORMANCE]


def _corner(kind: VehicleKind = VehicleKind.FIXED_WING) -> Operation:
    """1100 m east, then 1100 m north, at 100 m and 22 m/s (the corner at t = 50 s), filed
    with a 10 m flight geometry and a 30 m operational volume."""
    pts = [(0.0, 0.0, 100.0, 0.0), (1100.0, 0.0, 100.0, 50.0), (1100.0, 1100.0, 100.0, 100.0)]
    return _as(operation("P", pts, fg=10, ov=30), kind)


def _inside(d_m: float) -> tuple[float, float, float]:
    """``d_m`` off both legs inside the turn (north-west of the corner), at 100 m."""
    return (1100.0 - d_m, d_m, 100.0)


@pytest.mark.parametrize("d_m", [12.0, 18.0, 23.0])
def test_a_plane_cutting_the_corner_on_its_radius_is_conformant(d_m: float) -> None:
    """ArduPlane's 10-13 m off the plan in the turn, and up to the arc of 80 m (23.4 m off
    both legs at its middle)."""
    assert _kinds(_corner(), 50.0, _inside(d_m)) == []


def test_inside_its_arc_or_outside_the_corner_it_is_not() -> None:
    cut_m = FIXED_WING_TURN_RADIUS_M * (1.0 - 1.0 / math.sqrt(2.0))  # 23.4 m off the legs
    assert _kinds(_corner(), 50.0, _inside(cut_m + 12.0)) == [ThreatKind.UAS_IN_CV]
    outside = (1100.0 + 12.0, -12.0, 100.0)  # 12 m off the legs outside: no arc there
    assert _kinds(_corner(), 50.0, outside) == [ThreatKind.UAS_IN_CV]
    x, y, _ = _inside(18.0)
    assert _kinds(_corner(), 50.0, (x, y, 115.0)) == [ThreatKind.UAS_IN_CV]


def test_a_plane_overshooting_the_next_leg_after_its_turn_is_conformant() -> None:
    """Real ArduPlane turned 50 m before a 90 deg corner and ran on 26 m outside the next leg
    about 100 m past the corner, back within 10 m by 200 m: allowed up to
    R (1 - cos 90) - 50 sin 90 = 30 m outside for R past the corner, back to 0 at 3 R."""
    assert _kinds(_corner(), 54.0, (1100.0 + 26.0, 90.0, 100.0)) == []
    assert _kinds(_corner(), 58.0, (1100.0 + 20.0, 180.0, 100.0)) == []
    late = (1100.0 + 20.0, 400.0, 100.0)  # 400 m on, past 3 R: it should be back
    assert _kinds(_corner(), 50.0 + 400.0 / 22.0, late) == [ThreatKind.UAS_IN_CV]
    assert _kinds(_corner(VehicleKind.MULTIROTOR), 54.0, (1126.0, 90.0, 100.0)) == [
        ThreatKind.UAS_IN_CV
    ]


def test_a_multirotor_flies_its_corner() -> None:
    assert _kinds(_corner(VehicleKind.MULTIROTOR), 50.0, _inside(12.0)) == [ThreatKind.UAS_IN_CV]


def test_the_corner_counts_only_when_the_plane_may_be_there() -> None:
    """At t = 5 s the plane may be at most 150 m along (30 m/s): not at the corner."""
    table = pack_plans(
        [np.array([[0, 0, 100, 0], [1100, 0, 100, 50], [1100, 1100, 100, 100]], float)]
    )
    band = (np.array([80.0]), np.array([0.5]), np.array([0.3]))
    pos = np.array([_inside(20.0)])
    early = band_distance(table, pos, (np.array([0.0]), np.array([10.0])), band)
    at_corner = band_distance(table, pos, (np.array([40.0]), np.array([60.0])), band)
    assert at_corner[0] == 0.0
    assert early[0] > 800.0  # from the first 220 m of the first leg


def _climb(kind: VehicleKind = VehicleKind.FIXED_WING, up_m: float = 30.0) -> Operation:
    """1600 m north at 22 m/s from 100 m to ``100 + up_m``."""
    pts = [(0.0, 0.0, 100.0, 0.0), (0.0, 1600.0, 100.0 + up_m, 1600.0 / 22.0)]
    return _as(operation("P", pts, fg=10, ov=30), kind)


@pytest.mark.parametrize("north_m", [100.0, 400.0, 800.0])
def test_a_plane_climbing_first_is_conformant(north_m: float) -> None:
    """Climb first at 5 m/s: 30 m up within 300 m at 22 m/s, 20 m above the straight line
    at 400 m; it stays there to the waypoint."""
    z = 100.0 + min(30.0, north_m * 5.0 / 22.0)
    assert _kinds(_climb(), north_m / 22.0, (0.0, north_m, z)) == []
    assert _kinds(_climb(VehicleKind.MULTIROTOR), north_m / 22.0, (0.0, north_m, z)) != []


def test_a_plane_descending_first_is_conformant() -> None:
    z = 100.0 - 400.0 * 3.0 / 22.0  # 54.5 m down at 3 m/s: 45.5 m, the line 85 m
    assert _kinds(_climb(up_m=-60.0), 400.0 / 22.0, (0.0, 400.0, z)) == []


def test_above_its_steepest_climb_or_its_target_it_is_not() -> None:
    """Climb first is bounded by climb rate over minimum speed (0.5): 50 m up at 100 m."""
    assert _kinds(_climb(up_m=100.0), 100.0 / 22.0, (0.0, 100.0, 100.0 + 65.0)) != []
    assert _kinds(_climb(), 400.0 / 22.0, (0.0, 400.0, 130.0 + 12.0)) != []
    assert _kinds(_climb(), 400.0 / 22.0, (0.0, 400.0, 107.5 - 12.0)) != []


def test_turn_radius_from_speed_and_roll_limit() -> None:
    """v^2 / (g tan(roll)): the default 80 m is ArduPlane's default 45 deg at 28 m/s, and
    bounds PX4's 50 deg (FW_R_LIM) at 30 m/s."""
    assert turn_radius_m(28.0, 45.0) == pytest.approx(80.0, abs=0.5)
    assert turn_radius_m(24.0, 65.0) == pytest.approx(27.4, abs=0.2)
    assert turn_radius_m(30.0, 50.0) <= FIXED_WING_TURN_RADIUS_M
    with pytest.raises(ValueError, match="roll_limit_deg"):
        turn_radius_m(20.0, 90.0)
