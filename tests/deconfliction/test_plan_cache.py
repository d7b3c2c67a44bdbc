"""TD's plan cache holds the plans in use, not every candidate it ever verified: a
decision's candidates go when the decision's result is dropped (``gcs-utm bench soak``)."""

from __future__ import annotations

import gc

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.plan_cache import PlanCache
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import FlightPlan


def _plans_alive() -> int:
    gc.collect()
    return sum(isinstance(o, FlightPlan) for o in gc.get_objects())


def test_candidates_of_dropped_decisions_are_not_kept() -> None:
    snap, threat = sc.scenario_los_2uas()
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MonitoringConfig())
    assert td.resolve_loss_of_separation(threat, snap)  # warm: what stays is in place
    before = _plans_alive()
    for _ in range(5):
        alternatives = td.resolve_loss_of_separation(threat, snap)
        assert alternatives
        del alternatives
    # the snapshot's two plans are all TD may keep between decisions (each decision verifies
    # tens of candidates; a cache holding them would show them here)
    assert _plans_alive() <= before
    assert len(td._plans) <= len(snap.operations)


def test_an_entry_goes_with_its_plan() -> None:
    snap, _ = sc.scenario_los_2uas()
    plan_a, plan_b = (op.plan for op in snap.operations.values())
    del snap  # the operations held the plans too
    cache = PlanCache(sc.FRAME)
    local_a = cache.local(plan_a)
    assert cache.local(plan_a) is local_a  # converted once
    assert cache.max_speeds(plan_a) is cache.max_speeds(plan_a)
    cache.local(plan_b)
    cache.max_speeds(plan_b)
    assert len(cache) == 2
    del plan_b
    gc.collect()
    assert len(cache) == 1  # plan_b freed: its local form and speeds went with it
    assert cache.local(plan_a) is local_a
