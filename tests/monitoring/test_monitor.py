"""Monitor cycle: geofences in 4D, conformance, separation, intruders and threat life cycle."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, Polygon

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, cylinder, operation, polygon

from gcs_utm.core.monitoring import Monitor, MonitoringConfig, point_in_polygon
from gcs_utm.model import (
    AirspaceSnapshot,
    Geofence,
    Operation,
    PredictedTrajectories,
    ThreatKind,
    ThreatStatus,
    Track,
    TrackId,
)

STAR = [
    (np.cos(a) * (100 if i % 2 == 0 else 35), np.sin(a) * (100 if i % 2 == 0 else 35))
    for i, a in enumerate(np.linspace(0, 2 * np.pi, 10, endpoint=False))
]
U = [(0, 0), (300, 0), (300, 300), (200, 300), (200, 100), (100, 100), (100, 300), (0, 300)]


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31))
def test_winding_matches_shapely_on_concave_shapes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for verts in (STAR, U):
        v = np.array(verts, float)
        x = rng.uniform(v[:, 0].min() - 20, v[:, 0].max() + 20, 300)
        y = rng.uniform(v[:, 1].min() - 20, v[:, 1].max() + 20, 300)
        got = point_in_polygon(x, y, v[:, 0], v[:, 1])
        poly = Polygon(v)
        want = np.array([poly.covers(Point(a, b)) for a, b in zip(x, y, strict=True)])
        assert (got == want).all()


def _snapshot(
    t: float,
    states: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]],
    ops: list[Operation],
    fences: tuple[Geofence, ...] = (),
    *,
    stale: frozenset[str] = frozenset(),
    intruders: frozenset[str] = frozenset(),
    steps: int = 61,
) -> AirspaceSnapshot:
    """Constant-velocity prediction at 1 s from (position, velocity) per track."""
    tracks = {}
    pts = []
    k = np.arange(steps, dtype=float)
    for tid, (p, v) in states.items():
        coop = tid not in intruders
        tracks[TrackId(tid)] = Track(
            id=TrackId(tid),
            t_s=t,
            lat_deg=0.0,
            lon_deg=0.0,
            alt_amsl_m=p[2],
            east_m=p[0],
            north_m=p[1],
            vel_enu_mps=v,
            position_sigma_m=1.0,
            cooperative=coop,
            operation_id=tid if coop else None,  # type: ignore[arg-type]
            stale=tid in stale,
        )
        row = np.empty((steps, 4))
        row[:, :3] = np.array(p) + np.outer(k, v)
        row[:, 3] = t + k
        pts.append(row)
    pred = PredictedTrajectories(
        t_s=t,
        track_ids=tuple(TrackId(x) for x in states),
        points=np.array(pts).reshape(len(pts), steps, 4),
        sigma_m=np.ones((len(pts), steps)),
    )
    return AirspaceSnapshot(
        t_s=t,
        operations={o.id: o for o in ops},
        tracks=tracks,
        geofences=fences,
        prediction=pred,
    )


# Conformance compares with the whole plan line here, so only the tested condition fires.
LOOSE = {"conformance_time_tolerance_s": 1000.0}


def _line_op(name: str, y: float, z: float = 100.0) -> Operation:
    return operation(name, [(-5000, y, z, -500), (5000, y, z, 500)], fg=20, ov=40)


def test_separation_threat_persists_updates_and_closes_with_hysteresis() -> None:
    cfg = MonitoringConfig(close_cycles=2, **LOOSE)
    mon = Monitor(FRAME, cfg)
    ops = [_line_op("A", 0), _line_op("B", 0)]
    head_on = {"A": ((0, 0, 100), (10, 0, 0)), "B": ((600, 0, 100), (-10, 0, 0))}
    (t1,) = mon.cycle(_snapshot(0, head_on, ops))
    assert t1.kind is ThreatKind.LOSS_OF_SEPARATION and t1.status is ThreatStatus.OPEN
    assert t1.uas_ids == ("A", "B")
    # Minimum max(50, 40 + 40) = 80 m lost at (600 - 80) / 20 = 26 s; CPA at 30 s.
    assert t1.predicted_event_at_s == pytest.approx(26.0)
    assert t1.closest_approach_t_s == pytest.approx(30.0)
    assert t1.snapshot is not None and t1.snapshot.points.shape == (2, 61, 4)
    # Next cycle, same geometry one second later: no re-raise.
    later = {"A": ((10, 0, 100), (10, 0, 0)), "B": ((590, 0, 100), (-10, 0, 0))}
    assert mon.cycle(_snapshot(1, later, ops)) == []
    assert [t.id for t in mon.active()] == [t1.id]
    # Stale data for many cycles never closes it.
    for t in range(2, 8):
        assert mon.cycle(_snapshot(t, later, ops, stale=frozenset({"B"}))) == []
    assert len(mon.active()) == 1
    # B gets a new plan at 300 m and climbs to it: clear for two fresh cycles -> closed once.
    ops2 = [ops[0], _line_op("B", 0, z=300.0)]
    clear = {"A": ((10, 0, 100), (10, 0, 0)), "B": ((590, 0, 300), (-10, 0, 0))}
    assert mon.cycle(_snapshot(9, clear, ops2)) == []
    (closed,) = mon.cycle(_snapshot(10, clear, ops2))
    assert closed.status is ThreatStatus.CLOSED and closed.id == t1.id
    assert closed.message.endswith("closed: clear by the margin for 2 cycles"), closed.message
    assert mon.active() == []


def test_separation_does_not_close_inside_the_margin() -> None:
    cfg = MonitoringConfig(close_cycles=1, separation_close_margin_m=10.0, **LOOSE)
    mon = Monitor(FRAME, cfg)
    ops = [_line_op("A", 0), _line_op("B", 85)]  # B stays within its 20 m flight geometry
    near = {"A": ((0, 0, 100), (10, 0, 0)), "B": ((0, 70, 100), (10, 0, 0))}  # 70 < 80
    assert len(mon.cycle(_snapshot(0, near, ops))) == 1
    edge = {"A": ((0, 0, 100), (10, 0, 0)), "B": ((0, 85, 100), (10, 0, 0))}  # 85 < 80 + 10
    assert mon.cycle(_snapshot(1, edge, ops)) == []
    away = {"A": ((0, 0, 100), (10, 0, 0)), "B": ((0, 95, 100), (10, 0, 0))}
    (c,) = mon.cycle(_snapshot(2, away, ops))
    assert c.status is ThreatStatus.CLOSED


def test_thin_geofence_crossed_between_samples_is_a_conflict() -> None:
    # A 2 m wide wall at x in [299, 301]; the UAS moves 30 m per 1 s sample and no sample
    # falls inside it (x = 0, 30, ..., 270, 300 would: start at x = 5 instead).
    wall = polygon("wall", [(299, -500), (301, -500), (301, 500), (299, 500)])
    ops = [_line_op("A", 0)]
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    (t,) = mon.cycle(_snapshot(0, {"A": ((5, 0, 100), (30, 0, 0))}, ops, (wall,)))
    assert t.kind is ThreatKind.GEOFENCE_CONFLICT and t.geofence_id == "wall"
    assert t.predicted_event_at_s == pytest.approx((299 - 5) / 30)


def test_geofence_intrusion_band_and_activation_window() -> None:
    ops = [_line_op("A", 0)]
    inside = {"A": ((0, 0, 100), (10, 0, 0))}
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    (t,) = mon.cycle(_snapshot(0, inside, ops, (cylinder("c", (0, 0), 50),)))
    assert t.kind is ThreatKind.GEOFENCE_INTRUSION
    above = cylinder("c", (0, 0), 50, zlo=100.5, zhi=200)
    below = cylinder("c", (0, 0), 50, zlo=0, zhi=99.5)
    assert (
        Monitor(FRAME, MonitoringConfig(**LOOSE)).cycle(_snapshot(0, inside, ops, (above,))) == []
    )
    assert (
        Monitor(FRAME, MonitoringConfig(**LOOSE)).cycle(_snapshot(0, inside, ops, (below,))) == []
    )
    # A fence ahead that activates mid-horizon: the conflict time is the activation time if
    # the UAS is already inside then, else its entry.
    ahead = cylinder("late", (300, 0), 100, start=25.0)
    (t2,) = Monitor(FRAME, MonitoringConfig(**LOOSE)).cycle(_snapshot(0, inside, ops, (ahead,)))
    assert t2.kind is ThreatKind.GEOFENCE_CONFLICT and t2.predicted_event_at_s == 25.0
    gone = cylinder("old", (300, 0), 100, end=15.0)  # expires before the UAS reaches it
    assert Monitor(FRAME, MonitoringConfig(**LOOSE)).cycle(_snapshot(0, inside, ops, (gone,))) == []


def test_concave_u_geofence_notch_is_free() -> None:
    u = polygon("U", U)
    ops = [operation("A", [(150, 1000, 100, -500), (150, -1000, 100, 500)], fg=20, ov=40)]
    # Flying north up the notch centre (x = 150) from y = 320 down is outside; at y = 90 in.
    notch = {"A": ((150, 320, 100), (0, -2, 0))}  # reaches y = 200 at 60 s: never inside
    assert Monitor(FRAME, MonitoringConfig(**LOOSE)).cycle(_snapshot(0, notch, ops, (u,))) == []
    deep = {"A": ((150, 320, 100), (0, -5, 0))}  # reaches y = 100 at t = 44 s
    (t,) = Monitor(FRAME, MonitoringConfig(**LOOSE)).cycle(_snapshot(0, deep, ops, (u,)))
    assert t.predicted_event_at_s == pytest.approx(44.0)


def test_conformance_on_a_turn_and_phase_gate() -> None:
    # L-shaped plan: east 0 -> 1000 m (t 0..100), then north to (1000, 1000) (t 100..200).
    op = operation(
        "A",
        [(0, 0, 100, 0), (1000, 0, 100, 100), (1000, 1000, 100, 200)],
        fg=10,
        ov=30,
        home=(0, 0, 100),
    )
    cfg = MonitoringConfig(close_cycles=1)
    mon = Monitor(FRAME, cfg)
    # Cutting the corner at t = 100: 15 m inside the corner diagonally -> contingency volume.
    d = 15 / np.sqrt(2)
    (t,) = mon.cycle(_snapshot(100, {"A": ((1000 - d, d, 100), (0, 10, 0))}, [op]))
    assert t.kind is ThreatKind.UAS_IN_CV and t.closest_approach_m == pytest.approx(d)
    (t2,) = mon.cycle(_snapshot(101, {"A": ((960, 40, 100), (0, 10, 0))}, [op]))
    assert t2.kind is ThreatKind.UAS_OUT_OV and t2.id == t.id and t2.status is ThreatStatus.UPDATED
    (t3,) = mon.cycle(_snapshot(102, {"A": ((1000, 20, 100), (0, 10, 0))}, [op]))
    assert t3.status is ThreatStatus.CLOSED
    # Same 25 m offset near home during take-off: gated, no threat.
    # Same 25 m offset near home during take-off: gated, no threat.
    gated = Monitor(FRAME, cfg).cycle(_snapshot(1, {"A": ((5, 25, 105), (0, 0, 1))}, [op]))
    assert gated == []
    ungated = MonitoringConfig(gate_takeoff_landing=False)
    assert len(Monitor(FRAME, ungated).cycle(_snapshot(1, {"A": ((5, 25, 105), (0, 0, 1))}, [op])))


def test_intruder_against_uas() -> None:
    ops = [_line_op("A", 0)]
    states = {"A": ((0, 0, 100), (10, 0, 0)), "icao:abc123": ((2000, 0, 130), (-40, 0, 0))}
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    threats = mon.cycle(_snapshot(0, states, ops, intruders=frozenset({"icao:abc123"})))
    (t,) = [x for x in threats if x.kind is ThreatKind.INTRUDER]
    assert t.intruder_id == "icao:abc123" and t.uas_ids == ("A",)
    assert t.predicted_event_at_s == pytest.approx((2000 - 150) / 50)


def test_intruder_threat_closes_when_tracking_dropped_the_intruder() -> None:
    """A silent intruder is stale (its threat stays open: no evidence), and once tracking
    drops it (intruder_drop_after_s) the threat closes: nothing could close it any more."""
    ops = [_line_op("A", 0)]
    states = {"A": ((0, 0, 100), (10, 0, 0)), "icao:abc123": ((2000, 0, 130), (-40, 0, 0))}
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    intr = frozenset({"icao:abc123"})
    (t,) = [
        x
        for x in mon.cycle(_snapshot(0, states, ops, intruders=intr))
        if x.kind is ThreatKind.INTRUDER
    ]
    silent = frozenset({"icao:abc123"})
    for k in range(1, 4):
        assert mon.cycle(_snapshot(k, states, ops, intruders=intr, stale=silent)) == []
    (c,) = mon.cycle(_snapshot(4, {"A": states["A"]}, ops))
    assert c.id == t.id and c.status is ThreatStatus.CLOSED
    assert c.message.endswith("closed: intruder icao:abc123 is no longer tracked"), c.message


def test_an_unfiled_vehicle_on_the_ground_is_no_intruder() -> None:
    """A MAVLink vehicle without an operation is the intruder ``sysid:<n>``; standing on the
    ground below a UAS (``grounded_tracks``) it raises nothing, and the threat it raised while
    it flew closes at once when it lands."""
    ops = [_line_op("A", 0)]
    states = {"A": ((0, 0, 100), (0, 0, 0)), "sysid:2@h:1": ((20, 0, 90), (0, 0, 0))}
    intr = frozenset({"sysid:2@h:1"})
    ground = frozenset({TrackId("sysid:2@h:1")})
    quiet = Monitor(FRAME, MonitoringConfig(**LOOSE))
    for k in range(3):
        snap = replace(_snapshot(k, states, ops, intruders=intr), grounded_tracks=ground)
        assert [x for x in quiet.cycle(snap) if x.kind is ThreatKind.INTRUDER] == []
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    (t,) = [
        x
        for x in mon.cycle(_snapshot(0, states, ops, intruders=intr))
        if x.kind is ThreatKind.INTRUDER
    ]
    snap = replace(_snapshot(1, states, ops, intruders=intr), grounded_tracks=ground)
    (c,) = [x for x in mon.cycle(snap) if x.kind is ThreatKind.INTRUDER]
    assert c.id == t.id and c.status is ThreatStatus.CLOSED
    assert c.message.endswith("closed: intruder sysid:2@h:1 is on the ground"), c.message


def test_degenerate_snapshots() -> None:
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    empty = AirspaceSnapshot(t_s=0, operations={}, tracks={}, geofences=(), prediction=None)
    assert mon.cycle(empty) == []
    ops = [_line_op("A", 0)]
    assert mon.cycle(_snapshot(0, {"A": ((0, 0, 100), (0, 0, 0))}, ops, steps=1)) == []


def test_conformance_threat_survives_stale_track_and_closes_when_back_on_plan() -> None:
    op = _line_op("A", 0)  # fg 20 m, ov 40 m along y = 0
    mon = Monitor(FRAME, MonitoringConfig(close_cycles=2, **LOOSE))
    (t,) = mon.cycle(_snapshot(0, {"A": ((0, 30, 100), (10, 0, 0))}, [op]))
    assert t.kind is ThreatKind.UAS_IN_CV
    back = {"A": ((10, 0, 100), (10, 0, 0))}
    for k in range(1, 6):  # back on the plan, but the track is stale: nothing closes
        assert mon.cycle(_snapshot(k, back, [op], stale=frozenset({"A"}))) == []
    assert [x.id for x in mon.active()] == [t.id]
    # Just inside the flight geometry (within the 2 m close margin): still not closed.
    edge = {"A": ((10, 19, 100), (10, 0, 0))}
    assert mon.cycle(_snapshot(6, edge, [op])) == []
    assert mon.cycle(_snapshot(7, edge, [op])) == []
    assert mon.cycle(_snapshot(8, back, [op])) == []
    (c,) = mon.cycle(_snapshot(9, back, [op]))
    assert c.status is ThreatStatus.CLOSED and c.id == t.id


def test_persisting_conflict_over_many_cycles_is_one_threat() -> None:
    ops = [_line_op("A", 0), _line_op("B", 0)]
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    raised = []
    for k in range(20):  # closing head-on at 20 m/s, re-detected every cycle
        states = {
            "A": ((10.0 * k, 0, 100), (10, 0, 0)),
            "B": ((900 - 10.0 * k, 0, 100), (-10, 0, 0)),
        }
        raised += mon.cycle(_snapshot(k, states, ops))
    assert len({t.id for t in raised}) == 1
    assert [t.status for t in raised] == [ThreatStatus.OPEN]  # same event time: no updates


def test_cached_plans_and_fences_of_departed_operations_are_dropped() -> None:
    """A day of traffic comes and goes: the projections cached per operation and geofence
    stay bounded by what the airspace holds (they grew with every operation ever seen)."""
    mon = Monitor(FRAME, MonitoringConfig(**LOOSE))
    for i in range(100):
        op = _line_op(f"U{i}", 0)
        fence = cylinder(f"G{i}", (3000.0, 3000.0), 50.0)
        mon.cycle(_snapshot(i, {op.id: ((0, 0, 100), (10, 0, 0))}, [op], fences=(fence,)))
    assert 0 < len(mon._plan_cache) <= 20
    assert 0 < len(mon._fence_cache) <= 20
