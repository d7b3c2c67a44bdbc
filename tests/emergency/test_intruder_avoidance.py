"""Intruder avoidance (issue 22): EM recommends the best feasible climb, descent or lateral
avoidance of a non-cooperative intruder, verified against the intruder's predicted
straight-line path; with none feasible it proposes the safe command (hold)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import LocalPlan, plan_to_local
from gcs_utm.core.deconfliction.intruder import loses_minima
from gcs_utm.core.emergency import Decision, EmergencyConfig, EmergencyManager
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    CommandKind,
    Maneuver,
    Operation,
    ThreatKind,
    Track,
    TrackId,
)

MON = MonitoringConfig()
INTRUDER_SPEED_MPS = 20.0


def decide(op: Operation, ahead_m: float) -> tuple[Decision, Track]:
    """EM's decision on an intruder ``ahead_m`` east of the UAS at its altitude, flying
    west (head-on) at INTRUDER_SPEED_MPS."""
    lat, lon = sc.FRAME.point_to_wgs84(ahead_m, 0.0)
    intruder = Track(
        id=TrackId("icao:a1b2c3"),
        t_s=sc.T0_S,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=100.0,
        east_m=ahead_m,
        north_m=0.0,
        vel_enu_mps=(-INTRUDER_SPEED_MPS, 0.0, 0.0),
        position_sigma_m=5.0,
        cooperative=False,
    )
    snap = AirspaceSnapshot(
        t_s=sc.T0_S, operations={op.id: op}, tracks={intruder.id: intruder}, geofences=()
    )
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    em = EmergencyManager(sc.FRAME, EmergencyConfig(), td, MON)
    threat = sc.threat(ThreatKind.INTRUDER, [str(op.id)], intruder_id=intruder.id)
    return em.on_threat(threat, snap), intruder


def closest_minima_ratio(decision: Decision, intruder: Track) -> float:
    """Smallest max(horizontal / h_min, vertical / v_min) between the recommended plan and
    the intruder's straight-line path, at 0.25 s steps over the plan."""
    (rec,) = decision.recommendations
    assert rec.selected is not None and rec.selected.plan is not None
    lp = plan_to_local(rec.selected.plan, sc.FRAME)
    t = np.arange(float(lp.t[0]), float(lp.t[-1]), 0.25)
    pos, ok = lp.sample(t)
    ve = intruder.vel_enu_mps[0]
    e_i = intruder.east_m + ve * (t - intruder.t_s)
    dh = np.hypot(pos[:, 0] - e_i, pos[:, 1] - intruder.north_m)
    dv = np.abs(pos[:, 2] - intruder.alt_amsl_m)
    ratio = np.maximum(dh / MON.intruder_horizontal_m, dv / MON.intruder_vertical_m)
    return float(ratio[ok].min())


def test_head_on_intruder_gets_a_climb_that_keeps_the_intruder_minima() -> None:
    # 10 m/s east at 100 m AMSL, home 40 m below: the intruder closes at 30 m/s from 1 km
    # (33 s). The climb needs 50 m x (1 + margin) in that time, the answer and upload
    # included: feasible at the vehicle's climb rate, not at the share other deformations use.
    op = sc.make_operation("A", [(0, 0, 100), (1000, 0, 100)], home_enz=(0, 0, 60))
    d, intruder = decide(op, 1000.0)
    (rec,) = d.recommendations
    assert not d.escalations, d.escalations
    assert rec.selected is not None and rec.selected.maneuver is Maneuver.GO_UP
    assert "intruder icao:a1b2c3" in rec.selected.detail
    assert closest_minima_ratio(d, intruder) >= 1.0


def test_intruder_with_vertical_blocked_gets_a_lateral_avoidance() -> None:
    # A 20 m altitude band leaves no room to climb or descend 50 m: the UAS turns aside.
    op = sc.make_operation("A", [(0, 0, 100), (3000, 0, 100)])
    op = replace(op, min_alt_amsl_m=90.0, max_alt_amsl_m=110.0)
    d, intruder = decide(op, 2500.0)
    (rec,) = d.recommendations
    assert not d.escalations, d.escalations
    assert rec.selected is not None
    assert rec.selected.maneuver in (Maneuver.GO_LEFT, Maneuver.GO_RIGHT)
    assert closest_minima_ratio(d, intruder) >= 1.0
    alt_m = [w.alt_amsl_m for w in rec.selected.plan.waypoints]  # type: ignore[union-attr]
    assert min(alt_m) >= 90.0 and max(alt_m) <= 110.0


def test_intruder_too_close_for_any_avoidance_gets_the_safe_command() -> None:
    # 300 m ahead, closing at 30 m/s: nothing flyable reaches the minima in 10 s.
    op = sc.make_operation("A", [(0, 0, 100), (1000, 0, 100)], home_enz=(0, 0, 60))
    d, _ = decide(op, 300.0)
    (rec,) = d.recommendations
    assert rec.selected is None and rec.command is not None
    assert rec.command.kind is CommandKind.HOLD
    (msg,) = d.escalations
    assert "no avoidance" in msg and "hold proposed" in msg
    assert any(a.action == "escalation" for a in d.audit)


def test_loses_minima_finds_the_first_step_inside_the_intruder_minima() -> None:
    # The safety net behind every candidate: the re-timed plan itself against the intruder.
    t0 = sc.T0_S
    intruder = LocalPlan(
        np.array([1000.0, 0.0]), np.array([0.0, 0.0]), np.array([100.0, 100.0]),
        np.array([t0, t0 + 50.0]),
    )  # fmt: skip

    def alt(alt_amsl_m: float) -> Alternative:
        op = sc.make_operation("A", [(0, 0, alt_amsl_m), (1000, 0, alt_amsl_m)])
        return Alternative(operation_id=op.id, maneuver=Maneuver.GO_UP, plan=op.plan, cost=0.0,
                           risk=0.0)  # fmt: skip

    minima = (MON.intruder_horizontal_m, MON.intruder_vertical_m)
    # same altitude, closing at 30 m/s: inside 150 m when 850 m have closed (28.3 s)
    lost = loses_minima(alt(100.0), intruder, sc.FRAME, t0, minima)
    assert lost is not None and lost - t0 == 29.0
    assert loses_minima(alt(151.0), intruder, sc.FRAME, t0, minima) is None
    assert loses_minima(alt(149.0), intruder, sc.FRAME, t0, minima) is not None
