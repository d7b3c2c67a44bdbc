"""A fixed wing's safe hold whose circle would enter a geofence is replaced by a command that
does not (issue 30, geofence intrusions: enc_3_0235_endpoint_crossing)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.decision import Case
from gcs_utm.core.emergency.fenced_hold import fence_free_hold
from gcs_utm.core.emergency.single import single
from gcs_utm.model import (
    AirspaceSnapshot,
    CommandKind,
    OperationId,
    ThreatKind,
    TrackId,
    VehicleKind,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import _track, make_em, sc

B = OperationId("B")
SPEED_MPS = 20.0


def _plane(now: float, fences: tuple[object, ...] = ()) -> AirspaceSnapshot:
    """B, a fixed wing filed north along e = 0 (at the origin now), turned away: its track is
    200 m east of its plan, flying east at 20 m/s."""
    t0 = now - 1000.0 / SPEED_MPS
    b = sc.make_operation(
        "B", [(0, -1000, 100), (0, 1000, 100)], t0_s=t0, speed_mps=SPEED_MPS, ov_m=25.0
    )
    b = replace(b, vehicle_kind=VehicleKind.FIXED_WING, max_climb_rate_mps=5.0)
    snap = sc.snapshot([b], list(fences), t_s=now)  # type: ignore[arg-type]
    return replace(snap, tracks={TrackId("B"): _track("B", 200.0, 0.0, SPEED_MPS, 0.0, now)})


def test_a_fixed_wing_hold_that_circles_into_a_fence_is_replaced() -> None:
    """No alternative for B, a fixed wing flying north 120 m west of a 60 m fence's centre
    (60 m from its edge) and 200 m short of it: held there it circles up to two turn radii
    (160 m) around, into the fence. EM
    proposes a command whose room enters no fence instead (the hold is named in the audit
    as entering G1); without the fence the hold stands."""
    now = sc.T0_S + 89.0
    fence = sc.cylinder("G1", 320.0, 0.0, 60.0)
    snap = _plane(now, (fence,))
    # north, 200 m before passing the fence's side
    snap = replace(snap, tracks={TrackId("B"): _track("B", 200.0, -200.0, 0.0, SPEED_MPS, now)})
    em = make_em()
    threat = sc.threat(ThreatKind.GEOFENCE_CONFLICT, ["B"], t_s=now, event_in_s=30.0)
    instead = fence_free_hold(em.ctx, threat, B, snap)
    assert instead is not None
    cmds, actions = instead
    assert cmds[B].kind is not CommandKind.HOLD or actions[B] != "hold", actions
    d = single(em.ctx, Case(threat, Action.REROUTE, now), B, snap, frozenset())
    (rec,) = d.recommendations
    assert rec.command == cmds[B]
    clear = replace(snap, geofences=())
    assert fence_free_hold(em.ctx, threat, B, clear) is None
    d2 = single(make_em().ctx, Case(threat, Action.REROUTE, now), B, clear, frozenset())
    (rec2,) = d2.recommendations
    assert rec2.command is not None and rec2.command.kind is CommandKind.HOLD
