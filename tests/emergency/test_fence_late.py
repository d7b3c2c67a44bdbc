"""A geofence entry predicted sooner than a new plan can start gets an immediate command
(fence_late.py, issue 30 geofence intrusions: enc_5_0036_fence_head_on, a multirotor whose
plan was started inside the fence and flew 4.2 s in it)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.decision import SINGLE_MANEUVERS, Case
from gcs_utm.core.emergency.fence_late import fence_command, late_entry
from gcs_utm.core.emergency.single import single
from gcs_utm.model import (
    AirspaceSnapshot,
    CommandKind,
    GeofenceId,
    OperationId,
    Threat,
    ThreatKind,
    TrackId,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import _track, make_em, sc

B = OperationId("B")
SPEED_MPS = 6.0


def _towards_fence(edge_m: float) -> AirspaceSnapshot:
    """B, a multirotor at the origin flying east at 6 m/s on its plan, which crosses a 30 m
    fence whose edge is ``edge_m`` ahead."""
    now = sc.T0_S + 100.0
    b = sc.make_operation(
        "B", [(-600.0, 0.0, 100.0), (1200.0, 0.0, 100.0)], t0_s=sc.T0_S, speed_mps=SPEED_MPS
    )
    fence = sc.cylinder("G1", edge_m + 30.0, 0.0, 30.0)
    snap = sc.snapshot([b], [fence], t_s=now)
    return replace(snap, tracks={TrackId("B"): _track("B", 0.0, 0.0, SPEED_MPS, 0.0, now)})


def _threat(snap: AirspaceSnapshot, edge_m: float) -> Threat:
    return sc.threat(
        ThreatKind.GEOFENCE_CONFLICT,
        ["B"],
        t_s=snap.t_s,
        event_in_s=edge_m / SPEED_MPS,
        geofence_id=GeofenceId("G1"),
    )


def test_an_entry_sooner_than_a_plan_can_start_gets_the_hold() -> None:
    """The entry 5 s ahead, a new plan's start 7 s (answer 2, upload 3, margin 2): B is
    told to hold (it brakes 3 s from now, 7 m, and stops 5 m short of the fence), not given
    a plan that starts inside it."""
    snap = _towards_fence(30.0)
    em = make_em()
    threat = _threat(snap, 30.0)
    assert "sooner than a new plan can start" in late_entry(em.ctx, threat, snap.t_s)
    case = Case(threat, Action.REROUTE, snap.t_s)
    d = single(em.ctx, case, B, snap, SINGLE_MANEUVERS[Action.REROUTE])
    (rec,) = d.recommendations
    assert rec.selected is None or rec.selected.plan is None, rec.selected
    assert rec.command is not None and rec.command.kind is CommandKind.HOLD
    assert any("entry into G1 predicted in 5.0 s" in e for e in d.escalations), d.escalations


def test_an_entry_a_plan_is_in_time_for_gets_plans() -> None:
    """The entry 10 s ahead (a plan starts 7 s ahead), already past (the UAS stopped short
    of it under the command, the threat keeping its first time), or a conflict EM derived
    from another threat (a fence it creates): TD's plans are tried."""
    em = make_em()
    snap = _towards_fence(60.0)
    far = _threat(snap, 60.0)
    assert fence_command(em.ctx, Case(far, Action.REROUTE, snap.t_s), B, snap, far) is None
    late = _threat(snap, 30.0)
    alert = replace(late, kind=ThreatKind.ALERT_WARNING)  # B is blocked by the fence it makes
    assert fence_command(em.ctx, Case(alert, Action.REROUTE, snap.t_s), B, snap, late) is None
    past = replace(_threat(snap, 30.0), predicted_event_at_s=snap.t_s - 1.0)
    assert late_entry(em.ctx, past, snap.t_s) == ""
    loss = replace(_threat(snap, 30.0), kind=ThreatKind.LOSS_OF_SEPARATION)
    assert late_entry(em.ctx, loss, snap.t_s) == ""
