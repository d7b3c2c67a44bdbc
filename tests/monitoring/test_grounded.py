"""A vehicle on the ground is not traffic: Monitoring predicts nothing from its filed plan.

A mission uploaded to a disarmed vehicle is filed as if it took off at the filing; its track
(on the ground) is predicted along that plan. While the vehicle says it is on the ground
(``AirspaceSnapshot.grounded``) no threat is raised from it, and one raised while it flew
closes at once when it lands; once it takes off it is checked like any other UAS.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, operation

from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.model import (
    AirspaceSnapshot,
    OperationId,
    OperationState,
    PredictedTrajectories,
    ThreatKind,
    ThreatStatus,
    Track,
    TrackId,
)

A, B = OperationId("A"), OperationId("B")
STEPS = 61


def _crossing(t_s: float) -> AirspaceSnapshot:
    """Two operations whose plans (started at 0 s) cross at (0, 0, 100) at 30 s, each track
    predicted along its plan (as Tracking predicts a track that follows its plan)."""
    ops = {
        A: operation("A", [(-300, 0, 100, 0), (300, 0, 100, 60)], fg=20, ov=40),
        B: operation("B", [(0, -300, 100, 0), (0, 300, 100, 60)], fg=20, ov=40),
    }
    k = np.arange(STEPS, dtype=float)
    tracks, rows = {}, []
    for op_id, (p, v) in {
        A: ((-300.0 + 10 * t_s, 0.0, 100.0), (10.0, 0.0, 0.0)),
        B: ((0.0, -300.0 + 10 * t_s, 100.0), (0.0, 10.0, 0.0)),
    }.items():
        tracks[TrackId(op_id)] = Track(
            id=TrackId(op_id),
            t_s=t_s,
            lat_deg=0.0,
            lon_deg=0.0,
            alt_amsl_m=p[2],
            east_m=p[0],
            north_m=p[1],
            vel_enu_mps=v,
            position_sigma_m=1.0,
            cooperative=True,
            operation_id=op_id,
        )
        row = np.empty((STEPS, 4))
        row[:, :3] = np.array(p) + np.outer(k, v)
        row[:, 3] = t_s + k
        rows.append(row)
    pred = PredictedTrajectories(
        t_s=t_s,
        track_ids=(TrackId(A), TrackId(B)),
        points=np.array(rows),
        sigma_m=np.ones((2, STEPS)),
    )
    return AirspaceSnapshot(t_s=t_s, operations=ops, tracks=tracks, geofences=(), prediction=pred)


def _los(threats: list) -> list:  # type: ignore[type-arg]
    return [t for t in threats if t.kind is ThreatKind.LOSS_OF_SEPARATION]


def test_a_grounded_vehicle_s_filed_plan_raises_no_loss_until_it_takes_off() -> None:
    mon = Monitor(FRAME, MonitoringConfig())
    for t in (5.0, 6.0, 7.0):  # B disarmed on the ground: its plan started at 0 s
        snap = replace(_crossing(t), grounded=frozenset({B}), airborne=frozenset({A}))
        assert mon.cycle(snap) == [], t  # no separation, no conformance from B
    assert mon.active() == []
    # B takes off: traffic from now on, the crossing is predicted
    snap = replace(_crossing(8.0), airborne=frozenset({A, B}))
    (t1,) = _los(mon.cycle(snap))
    assert t1.status is ThreatStatus.OPEN and t1.uas_ids == (A, B)


def test_a_loss_threat_closes_at_once_when_a_vehicle_is_on_the_ground() -> None:
    mon = Monitor(FRAME, MonitoringConfig(close_cycles=5))
    (t1,) = _los(mon.cycle(replace(_crossing(5.0), airborne=frozenset({A, B}))))
    # B lands (armed, landed state on the ground) with its operation still active
    out = mon.cycle(replace(_crossing(6.0), grounded=frozenset({B}), airborne=frozenset({A})))
    (closed,) = _los(out)
    assert closed.id == t1.id and closed.status is ThreatStatus.CLOSED
    assert closed.message.endswith("closed: B is on the ground"), closed.message  # why
    assert mon.active() == []


def test_a_loss_threat_closes_at_once_when_the_other_operation_landed() -> None:
    mon = Monitor(FRAME, MonitoringConfig(close_cycles=5))
    (t1,) = _los(mon.cycle(replace(_crossing(5.0), airborne=frozenset({A, B}))))
    snap = _crossing(6.0)
    ops = dict(snap.operations)
    ops[B] = replace(ops[B], state=OperationState.LANDED)
    # landed and disarmed: the operation's own state says why first
    out = mon.cycle(replace(snap, operations=ops, grounded=frozenset({B}), airborne=frozenset({A})))
    (closed,) = _los(out)
    assert closed.id == t1.id and closed.status is ThreatStatus.CLOSED
    assert closed.message.endswith("closed: operation B landed"), closed.message
