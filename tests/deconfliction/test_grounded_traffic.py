"""A vehicle on the ground is not traffic for TD, whatever its filed plan says: a mission
uploaded to a disarmed vehicle is timed as if it took off at the filing, and is re-timed when
it does take off."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import loitering
from gcs_utm.model import OperationId, OperationState

T0 = sc.T0_S
G, M = OperationId("G"), OperationId("M")


def test_a_grounded_vehicle_s_started_plan_is_not_traffic() -> None:
    # G's mission (filed 20 s ago, active) crosses M's path at the origin in 60 s
    g = sc.make_operation("G", [(0.0, -800.0, 100.0), (0.0, 800.0, 100.0)], t0_s=T0 - 20.0)
    m = sc.make_operation("M", [(-600.0, 0.0, 100.0), (600.0, 0.0, 100.0)], t0_s=T0)
    flying = replace(sc.snapshot([g, m]), airborne=frozenset({G, M}))
    td = sc.build_manager().td
    until = T0 + 300.0
    assert [o.id for o in loitering.traffic(flying, {M}, sc.FRAME, until, ())] == [G]
    assert any("separation with G" in f for f in td.verify(m.plan, m, td.others(flying, {M}), ()))
    # G disarmed on the ground: not traffic, M's plan is clear
    ground = replace(flying, airborne=frozenset({M}), grounded=frozenset({G}))
    assert g.state is OperationState.ACTIVE and g.plan.start_t_s < T0
    assert loitering.traffic(ground, {M}, sc.FRAME, until, ()) == []
    assert td.verify(m.plan, m, td.others(ground, {M}), ()) == []
