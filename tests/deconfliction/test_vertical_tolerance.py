"""Vertical tracking tolerance: TD keeps both vehicles' vertical tolerances free between new
plans, as it does horizontally (a vehicle flies a new altitude a little off and late)."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_plans
from gcs_utm.envelope import implied
from gcs_utm.model import Maneuver, OperationId, ThreatKind

MON = MonitoringConfig()


def test_pair_minima_add_both_vertical_tolerances_in_cylinder_mode() -> None:
    a = sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)])
    b = sc.make_operation("B", [(0, -1000, 100), (0, 1000, 100)])
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    h, v = MON.effective_minima(10.0, 10.0)
    env = a.performance()
    assert env.vertical_tracking_tolerance_m() == 2.0  # multirotor default
    assert implied(True, 20.0, 3.0).vertical_tracking_tolerance_m() == 5.0  # fixed wing
    assert td.pair_minima(a, b) == (h + 10.0, v + 4.0)
    assert td.pair_minima(a, b, buffered=False) == (h, v)  # EM's second search: bare minima


def test_vertical_alternatives_keep_both_vertical_tolerances_free() -> None:
    # Two multirotors crossing at one altitude: every vertical alternative keeps the
    # effective vertical minimum plus both vehicles' vertical tolerances from the other's
    # plan. Before, only the bare vertical minimum (with the cords' margin) was kept: a pass
    # flown 4 cm inside it. Tolerances of 15 m each make the difference plain.
    env = replace(implied(False, 10.0, 3.0), vertical_tracking_error_m=15.0)
    a = replace(sc.make_operation("A", [(-1000, 0, 100), (1000, 0, 100)]), envelope=env)
    b = replace(sc.make_operation("B", [(0, -1000, 100), (0, 1000, 100)]), envelope=env)
    snap = sc.snapshot([a, b])
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(max_alt_amsl_m=400.0), MON)
    alts = td.resolve_loss_of_separation(sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"]), snap)
    _, v = MON.effective_minima(10.0, 10.0)
    buffered = replace(MON, separation_vertical_m=v + 30.0 - 0.5)
    vertical = [
        x
        for x in alts[OperationId("A")]
        if x.maneuver in (Maneuver.GO_UP, Maneuver.GO_DOWN) and "alone" in x.detail
    ]
    assert vertical
    for x in vertical:
        assert x.plan is not None
        assert plan_vs_plans(x.plan, a, [b], sc.FRAME, buffered) == [], x.detail
