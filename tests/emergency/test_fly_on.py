"""An immediate command is proposed only when it separates the UAS at least as well as
flying on: a fixed wing cannot stop, its hold circles where it is, and a hold chosen as
"the best there is" (ratio 0.06) sent a fixed wing on schedule circling into another UAS
(enc_1_0102_merge_overtaking, 9.3 m against 50 m)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import EmergencyConfig, EmergencyManager
from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.emergency.fly_on import FLY_ON
from gcs_utm.core.emergency.immediate import choose_commands, propose
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import AirspaceSnapshot, OperationId, ThreatKind, VehicleKind

MON = MonitoringConfig()
A = OperationId("A")


def _passing() -> AirspaceSnapshot:
    """A fixed wing eastbound between two multirotors westbound 40 m to its north and to
    its south (minima 50 m), meeting 6 s after the snapshot: flying on, they pass at 40 m;
    a turn either way takes the fixed wing towards one of them. Its altitude band leaves no
    room to climb or descend (climbing or descending straight on would add to flying on)."""
    a = sc.make_operation("A", [(-2000, 0, 100), (2000, 0, 100)], speed_mps=20.0, ov_m=25.0)
    a = replace(a, vehicle_kind=VehicleKind.FIXED_WING, min_alt_amsl_m=99.5, max_alt_amsl_m=100.5)
    others = []
    for name, north_m in (("B", 40), ("C", -40)):
        b = sc.make_operation(
            name, [(600, north_m, 100), (-600, north_m, 100)], speed_mps=6.0, ov_m=15.0
        )
        others.append(
            replace(
                b,
                plan=replace(
                    b.plan,
                    waypoints=tuple(
                        replace(w, t_s=w.t_s + 2000.0 / 20.0 - 600.0 / 6.0)
                        for w in b.plan.waypoints
                    ),
                ),
            )
        )
    return sc.snapshot([a, *others], t_s=sc.T0_S + 2000.0 / 20.0 - 6.0)


def test_no_command_when_every_command_separates_less_than_flying_on() -> None:
    snap = _passing()
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    choice = choose_commands(td, snap, [A], snap.t_s + 2.0, snap.t_s + 6.0, {A: 1})
    assert choice is not None
    assert choice.commands == {} and not choice.clear
    h_min_m, _ = td.pair_minima(snap.operations[A], snap.operations[OperationId("B")])
    assert choice.ratio == pytest.approx(40.0 / h_min_m, abs=0.02)  # TD's buffered minima
    commanded = [x for x in choice.tried if x["commands"] != FLY_ON]
    assert commanded and all(float(str(x["ratio"])) < choice.ratio for x in commanded)


def test_flying_on_is_a_warning_not_a_command_and_the_case_is_retried() -> None:
    snap = _passing()
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    em = EmergencyManager(sc.FRAME, EmergencyConfig(), td, MON)
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], t_s=snap.t_s, event_in_s=4.0)
    case = Case(threat=threat, action=Action.ALTERNATIVE_PLANS, attempt_t_s=snap.t_s - 30.0)
    d = propose(em.ctx, case, snap, "t1: loss predicted in 4.0 s", [A])
    assert d.recommendations == () and d.escalations == () and d.commands == ()
    assert d.warnings and "flying on" in d.warnings[0]
    assert case.attempt_t_s == snap.t_s  # decided again after retry_after_s
