"""Tracker behaviour a user relies on: tracking accuracy, fusion, association, rejection of
bad measurements without touching the state, staleness, prediction and snapshots."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import FRAME, T0, meas, new_tracker, operation, plan_from_local

from gcs_utm.core.tracking import Tracker, TrackingConfig, current_waypoint
from gcs_utm.model import Measurement, MeasurementSource, TrackId

ADSB = MeasurementSource.ADSB


def _state(tr: Tracker, tid: str) -> tuple[tuple[float, ...], np.ndarray]:
    t = tr.tracks()[TrackId(tid)]
    return (t.t_s, t.east_m, t.north_m, t.alt_amsl_m, *t.vel_enu_mps), tr.covariance(TrackId(tid))


@settings(max_examples=25, deadline=None)
@given(
    v=st.tuples(st.floats(-30, 30), st.floats(-30, 30), st.floats(-3, 3)),
    seed=st.integers(0, 2**32 - 1),
)
def test_constant_velocity_target_is_tracked_within_noise(
    v: tuple[float, float, float], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    tr = new_tracker()
    sigma_h, sigma_v = 3.0, 5.0
    for k in range(40):
        e, n, a = 100 + v[0] * k, -50 + v[1] * k, 200 + v[2] * k
        tr.ingest(
            [
                meas(
                    e + rng.normal() * sigma_h,
                    n + rng.normal() * sigma_h,
                    a + rng.normal() * sigma_v,
                    T0 + k,
                    eph_m=sigma_h,
                    epv_m=sigma_v,
                )
            ]
        )
    track = tr.tracks()[TrackId("sysid:1")]
    k = 39
    # The filtered error is well below one measurement sigma; 3 sigma never flakes.
    assert math.hypot(track.east_m - (100 + v[0] * k), track.north_m - (-50 + v[1] * k)) < (
        3 * sigma_h
    )
    assert abs(track.alt_amsl_m - (200 + v[2] * k)) < 3 * sigma_v
    # The velocity error is consistent with the filter's own velocity covariance (5 sigma).
    cov = tr.covariance(TrackId("sysid:1"))
    for axis in range(3):
        assert abs(track.vel_enu_mps[axis] - v[axis]) < 5 * math.sqrt(cov[3 + axis, 3 + axis])
    assert track.position_sigma_m < math.sqrt(2 * sigma_h**2 + sigma_v**2)


@settings(max_examples=25, deadline=None)
@given(
    shift=st.tuples(st.floats(-5000, 5000), st.floats(-5000, 5000), st.floats(-100, 100)),
    seed=st.integers(0, 2**32 - 1),
)
def test_translating_all_inputs_translates_the_track(
    shift: tuple[float, float, float], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(15, 3)) * 5 + np.arange(15)[:, None] * np.array([8.0, 3.0, 0.5])
    out = []
    for de, dn, da in [(0.0, 0.0, 0.0), shift]:
        tr = new_tracker()
        for k, (e, n, a) in enumerate(pts):
            tr.ingest([meas(e + de, n + dn, 300 + a + da, T0 + k)])
        t = tr.tracks()[TrackId("sysid:1")]
        out.append((np.array([t.east_m, t.north_m, t.alt_amsl_m]), t.vel_enu_mps))
    # WGS84 round trips cost micrometres, not more.
    np.testing.assert_allclose(out[1][0] - out[0][0], shift, atol=1e-4)
    np.testing.assert_allclose(out[1][1], out[0][1], atol=1e-5)


@settings(max_examples=30, deadline=None)
@given(
    steps=st.lists(
        st.tuples(
            st.floats(-2.0, 3.0),  # time step, negative = out of order
            st.floats(-30, 30),
            st.floats(-30, 30),
            st.sampled_from([None, 0.0, 0.5, 50.0]),
            st.booleans(),
        ),
        min_size=1,
        max_size=30,
    )
)
def test_covariance_stays_symmetric_psd(
    steps: list[tuple[float, float, float, float | None, bool]],
) -> None:
    tr = new_tracker()
    t = T0
    for dt, e, n, eph, adsb in steps:
        t += dt
        m = meas(
            e,
            n,
            100.0,
            t,
            eph_m=eph,
            source=ADSB if adsb else MeasurementSource.TELEMETRY,
            vel_ned_mps=(1.0, 2.0, 0.0) if eph == 0.5 else None,
        )
        tr.ingest([m])
        cov = tr.covariance(TrackId("sysid:1"))
        assert np.array_equal(cov, cov.T)
        assert np.linalg.eigvalsh(cov).min() >= -1e-9


def _fused_cov(sources: list[tuple[MeasurementSource, float]]) -> float:
    tr = new_tracker()
    tr.set_operations(
        [operation("op1", plan_from_local("op1", [(0, 0, 100, T0)]), icao24="abc123")]
    )
    for src, eph in sources:
        tr.ingest([meas(0, 0, 100, T0, source=src, eph_m=eph, epv_m=eph, icao24="abc123")])
    return float(np.trace(tr.covariance(TrackId("op1"))[:3, :3]))


def test_fusing_two_sources_beats_either() -> None:
    tel = (MeasurementSource.TELEMETRY, 2.0)
    adsb = (ADSB, 10.0)
    both = _fused_cov([tel, adsb])
    assert both < _fused_cov([tel])
    assert both < _fused_cov([adsb])


def test_telemetry_and_adsb_of_one_uas_update_one_track() -> None:
    tr = new_tracker()
    tr.set_operations(
        [operation("op1", plan_from_local("op1", [(0, 0, 100, T0)]), sys_id=7, icao24="abc123")]
    )
    stats = tr.ingest(
        [
            meas(0, 0, 100, T0, sys_id=7),
            meas(1, 0, 100, T0 + 0.5, source=ADSB, sys_id=None, icao24="abc123"),
            meas(2, 0, 100, T0 + 1.0, sys_id=7),
        ]
    )
    assert stats.accepted == 3
    assert stats.new_tracks == (TrackId("op1"),)
    tracks = tr.tracks()
    assert list(tracks) == [TrackId("op1")]
    assert tracks[TrackId("op1")].updates == 3
    assert tracks[TrackId("op1")].cooperative


def test_unknown_adsb_is_a_non_cooperative_intruder_until_claimed() -> None:
    tr = new_tracker()
    tr.set_operations([operation("op1", plan_from_local("op1", [(0, 0, 100, T0)]), sys_id=1)])
    stats = tr.ingest(
        [meas(500, 500, 900, T0, source=ADSB, sys_id=None, icao24="4ca7b3"), meas(0, 0, 100, T0)]
    )
    assert stats.new_intruders == (TrackId("icao:4ca7b3"),)
    intruder = tr.tracks()[TrackId("icao:4ca7b3")]
    assert not intruder.cooperative
    assert intruder.operation_id is None
    assert tr.tracks()[TrackId("op1")].cooperative
    # Once an operation declares that ICAO address, the intruder track disappears and the
    # aircraft's next report updates the operation's track.
    tr.set_operations(
        [
            operation("op1", plan_from_local("op1", [(0, 0, 100, T0)]), sys_id=1),
            operation(
                "op2", plan_from_local("op2", [(500, 500, 900, T0)]), sys_id=2, icao24="4ca7b3"
            ),
        ]
    )
    assert TrackId("icao:4ca7b3") not in tr.tracks()
    tr.ingest([meas(501, 500, 900, T0 + 1, source=ADSB, sys_id=None, icao24="4ca7b3")])
    assert tr.tracks()[TrackId("op2")].cooperative


def test_vehicles_sharing_a_system_id_on_other_addresses_are_separate_until_claimed() -> None:
    import dataclasses

    tr = new_tracker()
    a = dataclasses.replace(meas(0, 0, 100, T0), vehicle="10.0.0.1:14550")
    b = dataclasses.replace(meas(2_000, 0, 100, T0), vehicle="10.0.0.2:14550")
    stats = tr.ingest([a, b])
    assert set(stats.new_intruders) == {
        TrackId("sysid:1@10.0.0.1:14550"),
        TrackId("sysid:1@10.0.0.2:14550"),
    }
    # 2 km apart at the same time: one merged track would have gated one of them away
    assert stats.accepted == 2
    # an operation flown by system id 1 claims them: the intruder tracks go
    tr.set_operations([operation("op1", plan_from_local("op1", [(0, 0, 100, T0)]), sys_id=1)])
    assert set(tr.tracks()) == set()
    tr.ingest([dataclasses.replace(meas(1, 0, 100, T0 + 1), vehicle="10.0.0.1:14550")])
    assert set(tr.tracks()) == {TrackId("op1")}


@pytest.mark.parametrize(
    ("bad", "reason"),
    [
        (lambda: meas(10, 0, 100, T0 + 4), "out_of_order"),
        (lambda: meas(0, 0, 100, T0 + 5), "duplicate"),
        (lambda: meas(float("nan"), 0, 100, T0 + 6), "invalid"),
        (lambda: meas(0, 0, float("nan"), T0 + 6), "invalid"),
        (lambda: meas(0, 0, 100, T0 + 6, eph_m=float("nan")), "invalid"),
        (lambda: meas(0, 0, 100, T0 + 6, vel_ned_mps=(float("inf"), 0, 0)), "invalid"),
        (lambda: meas(1_000_000, 0, 100, T0 + 6), "gate"),  # 1,000 km jump
        (lambda: meas(1_000, 0, 100, T0 + 6), "gate"),  # 1 km in 1 s
        (lambda: meas(0, 0, 100, T0 + 6, vel_ned_mps=(1000.0, 0, 0)), "gate"),  # 1 km/s
        (lambda: meas(0, 0, 100, T0 + 600), "invalid"),  # captured after it was received
    ],
)
def test_bad_measurements_are_counted_and_never_move_the_track(bad: object, reason: str) -> None:
    tr = new_tracker()
    for k in range(6):
        tr.ingest([meas(0, 0, 100, T0 + k)])
    before, cov_before = _state(tr, "sysid:1")
    m = bad()  # type: ignore[operator]
    if reason == "invalid" and m.capture_t_s == T0 + 600:
        m = Measurement(**{**{f: getattr(m, f) for f in m.__slots__}, "receipt_t_s": T0 + 6})
    stats = tr.ingest([m])
    assert stats.accepted == 0
    assert getattr(stats, reason) == 1
    assert stats.rejected == 1
    after, cov_after = _state(tr, "sysid:1")
    assert after == before
    assert np.array_equal(cov_after, cov_before)
    assert tr.counters[reason] == 1


def test_measurement_without_identity_is_invalid() -> None:
    tr = new_tracker()
    stats = tr.ingest([meas(0, 0, 100, T0, sys_id=None)])
    assert (stats.invalid, len(tr)) == (1, 0)


def test_reordering_within_a_batch_is_repaired() -> None:
    ms = [meas(2.0 * k, 0, 100, T0 + k) for k in range(10)]
    in_order = new_tracker()
    in_order.ingest(ms)
    shuffled = new_tracker()
    stats = shuffled.ingest(ms[::-1])
    assert stats.accepted == 10
    a, ca = _state(in_order, "sysid:1")
    b, cb = _state(shuffled, "sysid:1")
    assert a == b
    assert np.array_equal(ca, cb)


def test_many_tracks_in_one_batch_equal_separate_tracking() -> None:
    """The vectorised rounds give every track exactly what it gets when tracked alone."""
    rng = np.random.default_rng(3)
    ms = [
        meas(float(e), float(n), 100, T0 + k + 0.1 * i, sys_id=i + 1)
        for k in range(5)
        for i, (e, n) in enumerate(rng.normal(size=(20, 2)) * 100 + k)
    ]
    together = new_tracker()
    together.ingest(ms)
    for i in range(20):
        alone = new_tracker()
        for m in ms:
            if m.sys_id == i + 1:
                alone.ingest([m])
        a, ca = _state(together, f"sysid:{i + 1}")
        b, cb = _state(alone, f"sysid:{i + 1}")
        np.testing.assert_allclose(a, b, rtol=1e-12)
        np.testing.assert_allclose(ca, cb, rtol=1e-12)


_report = st.tuples(
    st.integers(1, 4),  # sys_id
    st.sampled_from(["", "10.0.0.1:14550"]),  # vehicle
    st.integers(0, 8),  # capture time in steps of 0.5 s: ties, duplicates, out of order
    st.sampled_from(list(MeasurementSource)),
    st.floats(-30.0, 30.0),  # east
    st.sampled_from([0.0, 0.0, 0.0, 5_000.0]),  # a jump the gate rejects
    st.one_of(st.none(), st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-5, 5))),
    st.sampled_from([None, 0.5, 4.0, math.nan]),  # eph
)


@settings(max_examples=80, deadline=None)
@given(
    first=st.lists(_report, max_size=6),
    batches=st.lists(st.lists(_report, max_size=14), min_size=1, max_size=4),
)
def test_a_batch_equals_its_measurements_one_by_one_in_capture_time_order(
    first: list[tuple[int, str, int, MeasurementSource, float, float, object, object]],
    batches: list[list[tuple[int, str, int, MeasurementSource, float, float, object, object]]],
) -> None:
    """Whatever a batch holds (several measurements of a track, duplicates, out-of-order,
    gated, invalid, new tracks, restarts), ingesting it equals ingesting its measurements
    one at a time sorted by capture time (stable): the same counts and bit-for-bit the same
    states and covariances. The single-measurement call is the simple path (one round, one
    track), so this checks the rounds and the fast paths against it."""

    def build(
        reports: list[tuple[int, str, int, MeasurementSource, float, float, object, object]],
        t0: float,
    ) -> list[Measurement]:
        out = []
        for sys_id, vehicle, step, source, east, jump, vel, eph in reports:
            m = meas(
                east + jump,
                0.3 * east,
                100.0 + east / 10.0,
                t0 + 0.5 * step,
                source=source,
                sys_id=sys_id,
                vel_ned_mps=vel,  # type: ignore[arg-type]
                eph_m=eph,  # type: ignore[arg-type]
            )
            out.append(dataclasses.replace(m, vehicle=vehicle))
        return out

    cfg = {"stale_after_s": 1.0, "gate_reset_count": 1}
    batched = new_tracker(**cfg)
    single = new_tracker(**cfg)
    for k, reports in enumerate([first, *batches]):
        ms = build(reports, T0 + 2.0 * k)
        got = batched.ingest(ms)
        want = [single.ingest([m]) for m in sorted(ms, key=lambda m: m.capture_t_s)]
        for name in ("accepted", "out_of_order", "duplicate", "invalid", "gate", "reinitialised"):
            assert getattr(got, name) == sum(getattr(w, name) for w in want), name
        assert sorted(got.new_intruders) == sorted(t for w in want for t in w.new_intruders)
        assert batched.counters == single.counters
        assert batched.tracks() == single.tracks()
        for tid in batched.tracks():
            assert np.array_equal(batched.covariance(tid), single.covariance(tid))
        updated_b = {t.id: t for t in batched.take_updated()}
        updated_s = {t.id: t for t in single.take_updated()}
        assert updated_b == updated_s


def test_stale_raised_once_and_revived_by_a_measurement() -> None:
    tr = new_tracker(stale_after_s=5.0)
    tr.ingest([meas(0, 0, 100, T0)])
    assert tr.check_stale(T0 + 4.0) == []
    assert tr.check_stale(T0 + 6.0) == [TrackId("sysid:1")]
    assert tr.check_stale(T0 + 7.0) == []
    assert tr.tracks()[TrackId("sysid:1")].stale
    # The uncertainty of a stale track keeps growing with its silence.
    s1 = tr.predict(T0 + 7.0).sigma_m[0, 0]
    s2 = tr.predict(T0 + 20.0).sigma_m[0, 0]
    assert s2 > s1
    tr.ingest([meas(1, 0, 100, T0 + 8.0)])
    assert not tr.tracks()[TrackId("sysid:1")].stale
    assert tr.check_stale(T0 + 14.0) == [TrackId("sysid:1")]


def test_silent_intruders_are_dropped_but_uas_tracks_kept() -> None:
    tr = new_tracker(intruder_drop_after_s=30.0)
    tr.set_operations([operation("op1", plan_from_local("op1", [(0, 0, 100, T0)]), sys_id=1)])
    tr.ingest([meas(0, 0, 100, T0), meas(9, 9, 500, T0, source=ADSB, sys_id=None, icao24="aaaaaa")])
    tr.check_stale(T0 + 31.0)
    assert list(tr.tracks()) == [TrackId("op1")]
    assert tr.counters["intruders_dropped"] == 1


def test_wrong_first_fix_does_not_lock_the_track_out() -> None:
    tr = new_tracker(stale_after_s=5.0, gate_reset_count=3)
    tr.ingest([meas(50_000, 0, 100, T0)])  # a wild first fix, 50 km away
    for k in range(1, 12):
        tr.ingest([meas(0, 0, 100, T0 + k)])
    track = tr.tracks()[TrackId("sysid:1")]
    assert abs(track.east_m) < 10.0
    assert tr.counters["reinitialised"] == 1


def test_prediction_shapes_and_growing_uncertainty() -> None:
    tr = new_tracker(horizon_s=60.0, step_s=1.0)
    for k in range(5):
        tr.ingest([meas(10.0 * k, 0, 100, T0 + k), meas(0, 5.0 * k, 200, T0 + k, sys_id=2)])
    pred = tr.predict(T0 + 4)
    assert pred.points.shape == (2, 61, 4)
    assert pred.sigma_m.shape == (2, 61)
    np.testing.assert_allclose(pred.points[0, :, 3], T0 + 4 + np.arange(61))
    assert np.all(np.diff(pred.sigma_m, axis=1) > 0)
    # No plan: extrapolated with the filtered velocity (about 10 m/s east).
    assert pred.points[0, 60, 0] == pytest.approx(40 + 600, abs=20)


def test_prediction_follows_the_4d_plan_when_close_and_extrapolates_when_not() -> None:
    # Plan: east 100 m in 10 s, then north 100 m in 10 s.
    plan = plan_from_local(
        "op1", [(0, 0, 100, T0), (100, 0, 100, T0 + 10), (100, 100, 100, T0 + 20)]
    )
    tr = new_tracker()
    tr.set_operations([operation("op1", plan, sys_id=1, flight_geometry_m=10.0)])
    for k in range(6):
        tr.ingest([meas(10.0 * k, 0, 100, T0 + k, eph_m=0.5)])
    pred = tr.predict(T0 + 5)
    # 10 s later the plan has turned north: (100, 50); a straight line would say (150, 0).
    assert pred.points[0, 10, 0] == pytest.approx(100, abs=3)
    assert pred.points[0, 10, 1] == pytest.approx(50, abs=3)
    assert tr.tracks()[TrackId("op1")].next_waypoint == 1
    # 200 m off the plan the filter's velocity is used.
    tr2 = new_tracker()
    tr2.set_operations([operation("op1", plan, sys_id=1, flight_geometry_m=10.0)])
    for k in range(6):
        tr2.ingest([meas(10.0 * k, -200, 100, T0 + k, eph_m=0.5)])
    pred2 = tr2.predict(T0 + 5)
    assert pred2.points[0, 10, 0] == pytest.approx(150, abs=3)
    assert pred2.points[0, 10, 1] == pytest.approx(-200, abs=3)


_TURN = [(0, 0, 100, 0.0), (100, 0, 100, 10.0), (100, 100, 100, 20.0), (0, 100, 100, 30.0)]


def _fleet_tracker(which: set[str]) -> Tracker:
    """Up to three tracks: op1 on its plan (5 m off track), op2 200 m off its plan, and the
    ADS-B intruder abc123; six seconds of measurements each."""
    ops = [
        operation("op1", plan_from_local("op1", [(e, n, a, T0 + t) for e, n, a, t in _TURN])),
        operation(
            "op2", plan_from_local("op2", [(e, n, a, T0 + t) for e, n, a, t in _TURN]), sys_id=2
        ),
    ]
    tr = new_tracker()
    tr.set_operations(ops)
    for k in range(6):
        batch = []
        if "op1" in which:
            batch.append(meas(10.0 * k, 5.0, 100, T0 + k, eph_m=0.5))
        if "op2" in which:
            batch.append(meas(10.0 * k, -200.0, 100, T0 + k, sys_id=2, eph_m=0.5))
        if "abc123" in which:
            batch.append(meas(-5.0 * k, 50.0, 300, T0 + k, sys_id=None, icao24="abc123"))
        tr.ingest(batch)
    return tr


@pytest.mark.parametrize("t_s", [T0 + 2.5, T0 + 5.0, T0 + 9.0, T0 + 40.0])
def test_each_prediction_row_is_independent_of_the_others(t_s: float) -> None:
    """Plan-following, extrapolated and intruder rows predicted together equal each track
    predicted alone (the batched code splits rows by kind; nothing leaks). The times
    include one before the tracks' state time and one after the plan's end."""
    together = _fleet_tracker({"op1", "op2", "abc123"}).predict(t_s)
    for i, tid in enumerate(together.track_ids):
        alone = _fleet_tracker({str(tid).removeprefix("icao:")}).predict(t_s)
        assert alone.track_ids == (tid,)
        np.testing.assert_allclose(together.points[i], alone.points[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(together.sigma_m[i], alone.sigma_m[0], rtol=0, atol=1e-9)


def test_prediction_before_the_state_time_keeps_the_offset_without_amplifying_it() -> None:
    tr = _fleet_tracker({"op1"})
    pred = tr.predict(T0 + 2.0)  # 3 s before the track's last measurement
    # The plan is on north = 0; the track is ~5 m north of it. Before the state time the
    # offset is held (never grown by exp(+3 s / T)); afterwards it decays.
    north = pred.points[0, :, 1]
    offset_now = tr.tracks()[TrackId("op1")].north_m
    np.testing.assert_allclose(north[:4], offset_now, atol=1e-9)
    assert np.all(np.abs(north[4:8]) < abs(offset_now))


def test_current_waypoint_stays_right_while_flying_a_long_lawn_mower() -> None:
    """The tracker seeds each search with the previous segment; along a 20-lane pattern
    flown with noise, every cycle's waypoint equals a fresh full search."""
    pts: list[tuple[float, float, float, float]] = []
    t = 0.0
    for lane in range(20):
        xs = (0.0, 100.0) if lane % 2 == 0 else (100.0, 0.0)
        if lane:
            t += 1.5
        pts.append((xs[0], 15.0 * lane, 100.0, T0 + t))
        t += 10.0
        pts.append((xs[1], 15.0 * lane, 100.0, T0 + t))
    plan = plan_from_local("op1", pts)
    tr = new_tracker()
    tr.set_operations([operation("op1", plan)])
    rng = np.random.default_rng(5)
    wt = np.array([p[3] for p in pts])
    seen = set()
    for k in range(int(t)):
        e = float(np.interp(T0 + k, wt, [p[0] for p in pts])) + rng.normal()
        n = float(np.interp(T0 + k, wt, [p[1] for p in pts])) + rng.normal()
        tr.ingest([meas(e, n, 100.0, T0 + k, eph_m=1.0)])
        tracks, _ = tr.snapshot(T0 + k)
        track = tracks[TrackId("op1")]
        fresh = current_waypoint(
            plan,
            FRAME,
            east_m=track.east_m,
            north_m=track.north_m,
            alt_amsl_m=track.alt_amsl_m,
            t_s=T0 + k,
            ambiguity_m=10.0,
        )
        assert track.next_waypoint == fresh
        seen.add(fresh)
    assert len(seen) >= 35  # it really went down the pattern
    assert tr.plan_searches["window"] > tr.plan_searches["full"]


def test_snapshot_is_consistent_at_one_time() -> None:
    tr = new_tracker()
    tr.ingest([meas(0, 0, 100, T0), meas(0, 0, 100, T0 + 0.7, sys_id=2)])
    tr.ingest([meas(10, 0, 100, T0 + 1), meas(0, 10, 100, T0 + 1.7, sys_id=2)])
    tracks, pred = tr.snapshot(T0 + 3.0)
    assert {t.t_s for t in tracks.values()} == {T0 + 3.0}
    assert pred.t_s == T0 + 3.0
    for i, tid in enumerate(pred.track_ids):
        assert pred.points[i, 0, 0] == pytest.approx(tracks[tid].east_m)
        assert pred.points[i, 0, 1] == pytest.approx(tracks[tid].north_m)
    # The snapshot does not move the filter.
    assert tr.tracks()[TrackId("sysid:1")].t_s == T0 + 1


def test_config_ranges_are_enforced() -> None:
    with pytest.raises(ValueError, match=r"tracking\.step_s"):
        TrackingConfig(step_s=0.0)
    assert TrackingConfig().n_points == 61


def test_take_updated_hands_each_change_once() -> None:
    tr = new_tracker()
    tr.ingest([meas(0, 0, 100, T0), meas(0, 0, 100, T0, sys_id=2)])
    assert {t.id for t in tr.take_updated()} == {TrackId("sysid:1"), TrackId("sysid:2")}
    assert tr.take_updated() == []
    tr.ingest([meas(1, 0, 100, T0 + 1)])
    assert [t.id for t in tr.take_updated()] == [TrackId("sysid:1")]


def test_take_updated_in_chunks_hands_each_change_once_and_equals_the_tracks() -> None:
    """A limited take hands over at most that many changed tracks, each equal to what
    ``tracks()`` says of it (plans and waypoints included), and keeps the rest for later."""
    tr = new_tracker()
    plan = plan_from_local("op1", [(0, 0, 100, T0), (500, 0, 100, T0 + 100)])
    tr.set_operations([operation("op1", plan, sys_id=7)])
    tr.ingest([meas(3.0 * i, i, 100, T0 + 1, sys_id=i + 1) for i in range(45)])
    everything = tr.tracks()
    got: list[list[str]] = []
    while chunk := tr.take_updated(20):
        for t in chunk:
            assert t == everything[t.id]
        got.append([t.id for t in chunk])
    assert [len(c) for c in got] == [20, 20, 5]
    assert sorted(t for c in got for t in c) == sorted(everything)
    assert everything[TrackId("op1")].next_waypoint is not None
    assert tr.updated_count == 0 and tr.take_updated() == []
