"""A silent track (no position for a few periods, not yet stale) is dead-reckoned: its predicted
position is no conformance evidence, so Monitoring neither raises nor escalates conformance
from it; past the staleness limit tracking reports it (the link-loss threat); when positions
come back, conformance is judged from the real position. Its prediction stays traffic for
loss of separation.

Real tracker and monitor: A flies east to a turn at (100, 0) at T0 + 10, silent from T0 + 9;
dead-reckoned east it is 20 m off its plan at T0 + 12 (flight geometry 10 m) and 30 m at
T0 + 13 (outside its 20 m operational volume); it is stale (5 s) at T0 + 15."""

from __future__ import annotations

import dataclasses

import numpy as np

from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.tracking import Tracker
from gcs_utm.model import (
    AirspaceSnapshot,
    Measurement,
    Operation,
    OperationId,
    Threat,
    ThreatKind,
    Track,
    TrackId,
)
from tests.tracking.tracking_helpers import FRAME, T0, meas, new_tracker, operation, plan_from_local

ALT_M = 110.0
SPEED_MPS = 10.0
PERIOD_S = 0.2  # 5 Hz, as ArduPilot is asked for and PX4 sends


def _ops() -> list[Operation]:
    a = operation(
        "A",
        plan_from_local(
            "A", [(0, 0, ALT_M, T0), (100, 0, ALT_M, T0 + 10), (100, 2000, ALT_M, T0 + 210)]
        ),
        sys_id=1,
        flight_geometry_m=10.0,
    )
    # B southbound on A's leg north: their loss is first predicted (60 s ahead) at T0 + 12.
    b = operation(
        "B",
        plan_from_local("B", [(100, 1380, ALT_M, T0), (100, -2620, ALT_M, T0 + 400)]),
        sys_id=2,
        flight_geometry_m=10.0,
    )
    return [dataclasses.replace(o, operational_volume_m=20.0) for o in (a, b)]


def _a_at(t_s: float) -> tuple[float, float, tuple[float, float, float]]:
    """A on its plan: (east, north, velocity NED)."""
    dt = t_s - T0
    if dt <= 10:
        return SPEED_MPS * dt, 0.0, (0.0, SPEED_MPS, 0.0)
    return 100.0, SPEED_MPS * (dt - 10), (SPEED_MPS, 0.0, 0.0)


def _b(t_s: float) -> Measurement:
    north = 1380.0 - SPEED_MPS * (t_s - T0)
    return meas(100, north, ALT_M, t_s, sys_id=2, vel_ned_mps=(-SPEED_MPS, 0.0, 0.0))


def _times(start_s: float, end_s: float) -> list[float]:
    """Measurement times in (start, end], every PERIOD_S."""
    n = round((end_s - start_s) / PERIOD_S)
    return [start_s + PERIOD_S * (k + 1) for k in range(n)]


def _fly(tr: Tracker, start_s: float, end_s: float, *, a: bool) -> None:
    """Positions of B, and of A when ``a``, from ``start_s`` to ``end_s``."""
    for t in _times(start_s, end_s):
        batch = [_b(t)]
        if a:
            e, n, v = _a_at(t)
            batch.append(meas(e, n, ALT_M, t, sys_id=1, vel_ned_mps=v))
        tr.ingest(batch)


def _cycle(tr: Tracker, mon: Monitor, ops: list[Operation], t_s: float) -> list[Threat]:
    tracks, prediction = tr.snapshot(t_s)
    snap = AirspaceSnapshot(
        t_s=t_s,
        operations={o.id: o for o in ops},
        tracks=tracks,
        geofences=(),
        prediction=prediction,
    )
    return mon.cycle(snap)


def _conformance(threats: list[Threat]) -> list[Threat]:
    return [t for t in threats if t.kind in (ThreatKind.UAS_IN_CV, ThreatKind.UAS_OUT_OV)]


def _silent_until_stale() -> tuple[Tracker, Monitor, list[Operation]]:
    """Both fly to T0 + 9; A is then silent; cycles each second to T0 + 15 (A stale)."""
    ops = _ops()
    tr = new_tracker(stale_after_s=5.0)
    tr.set_operations(ops)
    mon = Monitor(FRAME, MonitoringConfig())
    t = T0 - PERIOD_S
    _fly(tr, t, T0 + 9, a=True)
    assert _conformance(_cycle(tr, mon, ops, T0 + 9)) == []
    seen_los = False
    for k in range(10, 16):
        _fly(tr, T0 + k - 1, T0 + k, a=False)
        stale = tr.check_stale(T0 + k)
        cols = tr.snapshot(T0 + k)[0].columns
        row = cols.operation_ids.index(OperationId("A"))
        a_east = float(cols.pos[row, 0])
        threats = _cycle(tr, mon, ops, T0 + k)
        # dead-reckoned east, off its plan by k - 10 periods of 10 m
        assert np.isclose(a_east, 90.0 + SPEED_MPS * (k - 9), atol=1.0)
        assert _conformance(threats) == [], f"conformance from a silent track at T0 + {k}"
        assert _conformance(mon.active()) == []
        seen_los |= any(t.kind is ThreatKind.LOSS_OF_SEPARATION for t in mon.active())
        # past the limit tracking reports the track stale once (the link-loss threat)
        assert (stale != []) is (k == 15)
    # the silent track's prediction is still traffic: the loss with B is predicted
    assert seen_los
    return tr, mon, ops


def test_silent_track_raises_no_conformance_and_is_judged_again_on_plan() -> None:
    tr, mon, ops = _silent_until_stale()
    # Positions back at T0 + 18, on the plan: no conformance threat.
    for s in _times(T0 + 17, T0 + 18):
        e, n, v = _a_at(s)
        tr.ingest([_b(s), meas(e, n, ALT_M, s, sys_id=1, vel_ned_mps=v)])
    assert _conformance(_cycle(tr, mon, ops, T0 + 18)) == []


def test_silent_track_back_off_its_plan_is_judged_from_the_real_position() -> None:
    tr, mon, ops = _silent_until_stale()
    # Positions back 40 m east of the plan (outside the 20 m volume): raised at once.
    for s in _times(T0 + 17, T0 + 18):
        _, n, v = _a_at(s)
        tr.ingest([_b(s), meas(140, n, ALT_M, s, sys_id=1, vel_ned_mps=v)])
    (conf,) = _conformance(_cycle(tr, mon, ops, T0 + 18))
    assert conf.kind is ThreatKind.UAS_OUT_OV and conf.uas_ids == ("A",)
    assert conf.closest_approach_m is not None
    assert np.isclose(conf.closest_approach_m, 40.0, atol=3.0)


def test_an_open_conformance_threat_is_not_escalated_from_a_silent_track() -> None:
    """A UAS_IN_CV threat open on real positions stays UAS_IN_CV while the track is only
    dead-reckoned (further off, outside the volume); measured there, it is escalated."""
    (op,) = [o for o in _ops() if o.id == "A"]
    mon = Monitor(FRAME, MonitoringConfig())

    def cycle(t_s: float, north_m: float, measured_t_s: float) -> list[Threat]:
        lat, lon = FRAME.point_to_wgs84(50.0, north_m)
        track = Track(
            id=TrackId("sysid:1"), t_s=t_s, lat_deg=lat, lon_deg=lon, alt_amsl_m=ALT_M,
            east_m=50.0, north_m=north_m, vel_enu_mps=(SPEED_MPS, 0.0, 0.0),
            position_sigma_m=1.0, cooperative=True, operation_id=op.id,
            measured_t_s=None if measured_t_s == t_s else measured_t_s,
        )  # fmt: skip
        snap = AirspaceSnapshot(
            t_s=t_s, operations={op.id: op}, tracks={track.id: track}, geofences=()
        )
        return _conformance(mon.cycle(snap))

    # on the first leg (y = 0) at T0 + 5: 15 m off is inside the volume (20 m), beyond 10 m
    (opened,) = cycle(T0 + 5, 15.0, T0 + 5)
    assert opened.kind is ThreatKind.UAS_IN_CV
    # dead-reckoned 30 m off, 2 s after the last position: no escalation, no update
    assert cycle(T0 + 7, 30.0, T0 + 5) == []
    assert [t.kind for t in _conformance(mon.active())] == [ThreatKind.UAS_IN_CV]
    # measured 30 m off: escalated
    (escalated,) = cycle(T0 + 8, 30.0, T0 + 8)
    assert escalated.kind is ThreatKind.UAS_OUT_OV and escalated.id == opened.id
