"""A fixed wing arriving at its last waypoint does not stop there: it loops out past it onto
its circle (the tracker's capture, :mod:`gcs_utm.core.tracking.loiter_entry`). TD's traffic,
verification and compatibility take it on that loop, not hovering at its end point
(``enc_8_0299_endpoint_near_threshold``: a turn verified against the plane "hovering" at its
end passed 76 m east of it as it arrived heading east, and met its loop at 6.9 m)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import loitering
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    Maneuver,
    Operation,
    OperationId,
    VehicleKind,
)

T0 = sc.T0_S
ALT_M = 100.0
SPEED_MPS = 22.0
END_IN_S = 40.0  # F reaches its last waypoint (the origin) this long after the snapshot
F, M = OperationId("F"), OperationId("M")


def _arriving_scene() -> AirspaceSnapshot:
    """F, a fixed wing, flies east at 22 m/s and ends its plan at the origin END_IN_S from
    now; M, a multirotor at F's altitude, flies north through (76, 0) as F arrives."""
    f = replace(
        sc.make_operation(
            "F",
            [(-SPEED_MPS * END_IN_S, 0.0, ALT_M), (0.0, 0.0, ALT_M)],
            t0_s=T0,
            speed_mps=SPEED_MPS,
        ),
        vehicle_kind=VehicleKind.FIXED_WING,
        cruise_speed_mps=SPEED_MPS,
    )
    m = sc.make_operation(
        "M", [(76.0, -200.0, ALT_M), (76.0, 200.0, ALT_M)], t0_s=T0 + END_IN_S - 18.0
    )
    snap = sc.snapshot([f, m])
    return replace(snap, airborne=frozenset({F, M}))


def _keep(op: Operation) -> Alternative:
    return Alternative(
        operation_id=op.id, maneuver=Maneuver.KEEP_PLAN, plan=op.plan, cost=0, risk=0
    )


def test_an_arriving_fixed_wing_is_traffic_on_its_entry_loop() -> None:
    snap = _arriving_scene()
    until = T0 + 120.0
    others = loitering.traffic(snap, {M}, sc.FRAME, until, ())
    plan = next(o.plan for o in others if o.id == F)
    assert plan.end_t_s >= until - loitering.CIRCLE_STEP_S
    lp = plan_to_local(plan, sc.FRAME)
    e, n, z = lp.coords(np.arange(T0 + END_IN_S, until, 0.5))
    # it goes on east past its end point and past M's line, then circles back
    assert e.max() > 80.0 and np.hypot(e, n).max() < 200.0
    assert np.allclose(z, ALT_M)


def test_td_does_not_keep_a_crossing_through_the_entry_loop() -> None:
    snap = _arriving_scene()
    td = sc.build_manager().td
    f, m = snap.operations[F], snap.operations[M]
    assert not td.compatible(_keep(f), _keep(m), snap)
    flags = td.verify(m.plan, m, td.others(snap, {M}), ())
    assert any("separation with F" in flag for flag in flags), flags
    # a multirotor ending there hovers at its end point, 76 m away: clear
    hover = replace(snap, operations={F: replace(f, vehicle_kind=VehicleKind.MULTIROTOR), M: m})
    assert td.compatible(_keep(hover.operations[F]), _keep(m), hover)
