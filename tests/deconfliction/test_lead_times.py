"""A new plan covers every instant from the moment the vehicle can have it: its first point
is at the earliest receipt (the answer plus the upload), also when that is less than one
lead-in step before the plan's start. Before, such a plan began up to a step after the
vehicle had it; until then Monitoring placed the UAS at the plan's first point, up to a step
of flight ahead of it, and EM commanded a fixed wing that was on schedule to hold: it circled
into another UAS (enc_1_0102_merge_overtaking, 9.3 m against 50 m)."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.deconfliction.lead_times import lead_times
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import Maneuver, OperationId


def test_lead_times_start_at_the_receipt() -> None:
    assert lead_times(3.0, 25.0, 5.0) == pytest.approx([3.0, 5.0, 10.0, 15.0, 20.0])
    assert lead_times(3.0, 5.0, 5.0) == pytest.approx([3.0])
    assert lead_times(0.0, 10.0, 5.0) == pytest.approx([0.0, 5.0])  # no point twice


def test_a_plan_starting_soon_after_the_receipt_is_timed_from_the_receipt() -> None:
    # Head-on multirotors; the vehicle can have the plan 2 s after the decision and the plan
    # starts 4 s after it (less than the 5 s lead-in step).
    snap, threat = sc.scenario_los_2uas()
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MonitoringConfig())
    now = snap.t_s
    alts = td.resolve_loss_of_separation(
        threat, snap, start_t_s=now + 4.0, lead_in_from_t_s=now + 2.0
    )
    new = [a for v in alts.values() for a in v if a.maneuver is not Maneuver.KEEP_PLAN]
    assert new
    for a in new:
        assert a.plan is not None
        first = a.plan.waypoints[0]
        assert first.t_s == pytest.approx(now + 2.0), a.maneuver
        # where the UAS is on its current plan then, not the manoeuvre's start point
        op = snap.operations[OperationId(a.operation_id)]
        e, n = sc.FRAME.point_to_local(first.lat_deg, first.lon_deg)
        was = plan_to_local(op.plan, sc.FRAME).position_at(now + 2.0)
        assert np.allclose([e, n, first.alt_amsl_m], was, atol=0.01)
