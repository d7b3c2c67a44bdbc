"""A multirotor's turns keep its stopping distance from a geofence's volume, in the direction
it flies (see gcs_utm/core/deconfliction/overshoot.py), the turn onto the first leg included."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import LocalPlan, fence_to_local
from gcs_utm.core.deconfliction.overshoot import overshoot_flags
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.envelope import implied
from gcs_utm.model import GeofenceId, Maneuver, OperationId, ThreatKind

MON = MonitoringConfig()
T0 = sc.T0_S


def _reversal(edge_e_m: float) -> tuple[LocalPlan, LocalPlan, list[object]]:
    """A filed plan east along n=0 and a new plan that reverses (about 170 degrees) at
    e=100, at 10 m/s; a square fence whose west edge is at ``edge_e_m``."""
    filed = LocalPlan(
        np.array([-500.0, 500.0]), np.array([0.0, 0.0]), np.full(2, 100.0), T0 + np.array([0, 100])
    )
    new = LocalPlan(
        np.array([0.0, 100.0, 0.0]),
        np.array([0.0, 0.0, 20.0]),
        np.full(3, 100.0),
        T0 + 50.0 + np.array([0.0, 10.0, 20.2]),
    )
    e = edge_e_m
    fence = sc.polygon("F", [(e, -200), (e + 300, -200), (e + 300, 200), (e, 200)])
    return new, filed, [fence]


def test_a_reversal_closer_to_a_fence_than_the_stopping_distance_is_flagged() -> None:
    op = sc.make_operation("A", [(-500, 0, 100), (100, 0, 100)])  # multirotor, OV 10 m
    stop_m = op.performance().stopping_distance_m(10.0)
    assert stop_m == 20.0  # 10 m/s braked at 2.5 m/s^2
    # The turn point 3 m from the fence's volume (13 m from its edge): 0.5-0.9 m inside
    # it when flown at 10 m/s. Flagged.
    new, filed, fences = _reversal(113.0)
    local = [fence_to_local(g, sc.FRAME) for g in fences]  # type: ignore[arg-type]
    flags = overshoot_flags(new, T0 + 50.0, filed, local, fences, op)  # type: ignore[arg-type]
    assert len(flags) == 1 and "waypoint 1" in flags[0] and "geofence F" in flags[0], flags
    # A stopping distance plus the volume away: clear.
    new, filed, fences = _reversal(100.0 + stop_m + 10.0 + 0.5)
    local = [fence_to_local(g, sc.FRAME) for g in fences]  # type: ignore[arg-type]
    assert overshoot_flags(new, T0 + 50.0, filed, local, fences, op) == []  # type: ignore[arg-type]
    # A fixed wing turns on its radius (turn_flags), not on a point.
    wing = replace(op, envelope=implied(True, 10.0, 3.0))
    new, filed, fences = _reversal(113.0)
    local = [fence_to_local(g, sc.FRAME) for g in fences]  # type: ignore[arg-type]
    assert overshoot_flags(new, T0 + 50.0, filed, local, fences, wing) == []  # type: ignore[arg-type]


def _first_leg_options(fence_e_m: float) -> tuple[set[Maneuver], dict[Maneuver, str]]:
    """A UAS flying east at 10 m/s, 7 m before its filed corner north, with a 100 m fence
    centred ``fence_e_m`` east of the corner: what is offered, what is dropped and why."""
    op = sc.make_operation("A", [(-500, 0, 100), (0, 0, 100), (0, 500, 100)])
    fence = sc.cylinder("F", fence_e_m, 0.0, 100.0)
    snap = sc.snapshot([op], [fence], t_s=T0 + 49.3)
    threat = sc.threat(
        ThreatKind.GEOFENCE_CONFLICT, ["A"], t_s=T0 + 49.3, geofence_id=GeofenceId("F")
    )
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(min_height_above_home_m=0.0), MON)
    alts = td.resolve_single(threat, OperationId("A"), snap)
    return {a.maneuver for a in alts}, {d.maneuver: d.reason for d in td.dropped}


def test_the_turn_onto_the_first_leg_keeps_the_stopping_distance() -> None:
    # The fence's volume begins 10 m past the corner, 17 m ahead of the UAS. Turning back
    # home from where it is (a reversal) or straight to its goal (a right angle) carries it
    # 19-20 m on east while it brakes: 7 m inside the volume. Before, only the turns between
    # a new plan's legs could be judged, never the one from the way the vehicle flies now
    # onto the first leg, and both were offered.
    offered, dropped = _first_leg_options(120.0)
    for m in (Maneuver.RETURN_HOME, Maneuver.DIRECT_TO_GOAL):
        assert m not in offered
        assert "at waypoint 0 overshoots" in dropped[m] and "geofence F" in dropped[m]
    # 15 m farther, both keep their stopping distance and are offered again.
    offered, _ = _first_leg_options(135.0)
    assert {Maneuver.RETURN_HOME, Maneuver.DIRECT_TO_GOAL} <= offered


def test_a_way_out_of_a_fence_is_not_refused_for_braking_on_the_way_out() -> None:
    # 10 m from the fence's volume at 10 m/s, inside TD's clearance: whatever it does, the
    # UAS brakes 19-20 m on towards the fence. The ways out (leave, hold outside, home) are
    # judged from their exit point on, so they are still offered.
    offered, dropped = _first_leg_options(113.0)
    assert {Maneuver.HOLD, Maneuver.RETURN_HOME} <= offered, dropped
