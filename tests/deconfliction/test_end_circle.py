"""A fixed wing circles its end point once its plan ends: a new plan (or a pair of EM's
alternatives) that hovers or passes within the minima of that circle is refused before the
circle is flown, not only once it is seen on the track (issue 30, losses created by accepted
plans: enc_7_0001, a multirotor's plan ending 68 m from a fixed wing's end point, an 80 m
circle, was accepted and flown 46.6 m from the circle)."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction.end_circle import circle_flags
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.tracking.loiter import loiter_radius_m
from gcs_utm.model import Alternative, Maneuver, Operation, OperationId, VehicleKind

T0 = sc.T0_S
ALT_M = 100.0
F, M = OperationId("F"), OperationId("M")


def _fixed_wing() -> Operation:
    """F flies east to the origin at 20 m/s, its plan ending there 30 s from now."""
    op = sc.make_operation("F", [(-600.0, 0.0, ALT_M), (0.0, 0.0, ALT_M)], speed_mps=20.0)
    return replace(op, vehicle_kind=VehicleKind.FIXED_WING, operational_volume_m=15.0)


def _multirotor(end_east_m: float) -> Operation:
    """M flies north to a point ``end_east_m`` east of F's end and ends there, 60 s from
    now (after F's end)."""
    return sc.make_operation(
        "M", [(end_east_m, -600.0, ALT_M), (end_east_m, 0.0, ALT_M)], speed_mps=10.0
    )


def _keep(op: Operation) -> Alternative:
    return Alternative(
        operation_id=op.id, maneuver=Maneuver.KEEP_PLAN, plan=op.plan, cost=0, risk=0
    )


def test_a_plan_ending_beside_a_fixed_wings_end_point_is_refused() -> None:
    f, m = _fixed_wing(), _multirotor(100.0)
    td = sc.build_manager().td
    radius_m = loiter_radius_m(f)
    h_min, _ = td.monitoring.effective_minima(f.operational_volume_m, m.operational_volume_m)
    assert radius_m >= 60.0 and radius_m + h_min > 100.0  # inside the circle's reach
    assert h_min + 20.0 < 100.0  # ...but clear of its centre, buffers included
    snap = sc.snapshot([f, m])
    flags = td.verify(m.plan, m, [f], ())
    assert any("separation with F" in x and "circle of F" in x for x in flags), flags
    # the same from the fixed wing's side, and in EM's joint selection
    assert any("separation with M" in x for x in td.verify(f.plan, f, [m], ()))
    assert not td.compatible(_keep(f), _keep(m), snap)
    assert not td.compatible(_keep(m), _keep(f), snap)


def test_a_plan_clear_of_the_circle_or_before_it_is_kept() -> None:
    f = _fixed_wing()
    td = sc.build_manager().td
    far = _multirotor(300.0)
    assert td.verify(far.plan, far, [f], ()) == []
    assert td.compatible(_keep(f), _keep(far), sc.snapshot([f, far]))
    # a multirotor that passes the end point and lands before the fixed wing gets there
    early = sc.make_operation("M", [(100.0, -100.0, ALT_M), (100.0, 0.0, ALT_M)], t0_s=T0)
    assert early.plan.end_t_s < f.plan.end_t_s
    assert td.verify(early.plan, early, [f], ()) == []


def test_two_fixed_wings_whose_circles_meet() -> None:
    f = _fixed_wing()
    g = sc.make_operation("G", [(150.0, -600.0, ALT_M), (150.0, 0.0, ALT_M)], speed_mps=20.0)
    g = replace(g, vehicle_kind=VehicleKind.FIXED_WING, operational_volume_m=15.0)
    lf, lg = plan_to_local(f.plan, sc.FRAME), plan_to_local(g.plan, sc.FRAME)
    minima = (50.0, 30.0)
    assert circle_flags(f, lf, [(g, lg)], lambda _a, _b: minima, False)
    far = replace(
        g, plan=sc.make_operation("G", [(400.0, -600.0, ALT_M), (400.0, 0.0, ALT_M)]).plan
    )
    assert not circle_flags(
        f, lf, [(far, plan_to_local(far.plan, sc.FRAME))], lambda _a, _b: minima, False
    )
