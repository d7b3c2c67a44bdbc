"""Position lanes and the C round: a lane entry is ingested exactly as its Measurement, and the
C kernel (``_kalman_c``) gives exactly what the NumPy reference gives -- the same counts,
bit for bit the same states and covariances -- whatever the batch holds (bad values of every
kind, gated jumps, duplicates, out of order, new tracks, unknown accuracies)."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import FRAME, T0, new_tracker

from gcs_utm.core.tracking import Tracker, kernel
from gcs_utm.core.tracking.layout import C_LAYOUT, NCOL
from gcs_utm.model import (
    LANE_STRIDE,
    Icao24,
    LaneSource,
    Measurement,
    MeasurementSource,
    PositionLane,
    SysId,
)

NAN = math.nan
INF = math.inf
C_BUILT = kernel._c is not None


def _no_c() -> mock._patch[None]:  # type: ignore[type-arg]
    """The NumPy reference alone, as without a C compiler."""
    return mock.patch.object(kernel, "_c", None)


# one lane entry: (source, step, east, north jump, alt, velocity, eph, epv, what is wrong)
_entry = st.tuples(
    st.integers(0, 4),  # source index: 5 vehicles, two of them sharing a system id
    st.integers(0, 6),  # capture time in steps of 0.4 s: ties, duplicates, out of order
    st.floats(-40.0, 40.0),
    st.sampled_from([0.0, 0.0, 0.0, 4_000.0]),  # a jump the gate rejects
    st.sampled_from([100.0, 100.0, 60_000.0, NAN]),  # alt (out of range, nan)
    st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-4, 4)),
    st.sampled_from([NAN, NAN, 0.3, 4.0, -1.0, INF]),  # eph (nan: unknown)
    st.sampled_from([NAN, NAN, 0.2, 6.0]),  # epv
    st.sampled_from(["", "", "", "lat", "t", "future", "fast", "inf_v", "rcv"]),
)
Entry = tuple[int, int, float, float, float, tuple[float, float, float], float, float, str]


def _lane() -> PositionLane:
    lane = PositionLane()
    for sys_id, vehicle in (
        (1, "10.0.0.1:14550"),
        (1, "10.0.0.2:14550"),
        (2, ""),
        (3, ""),
        (4, ""),
    ):
        lane.register(LaneSource(SysId(sys_id), "udpin:0.0.0.0:14550", vehicle))
    return lane


def _values(entries: list[Entry], t0: float) -> list[float]:
    out: list[float] = []
    for src, step, east, jump, alt, vel, eph, epv, wrong in entries:
        vn, ve, vd = vel
        lat, lon = FRAME.point_to_wgs84(east + jump + 100.0 * src, 0.5 * east)
        t = t0 + 0.4 * step
        rcv = t + 0.05
        if wrong == "lat":
            lat = 91.0
        elif wrong == "t":
            t = INF
        elif wrong == "future":
            t = rcv + 10.0
        elif wrong == "fast":
            vn = 500.0
        elif wrong == "inf_v":
            ve = -INF
        elif wrong == "rcv":
            rcv = NAN  # an unknown receipt time does not make a measurement invalid
        out += [src, rcv, t, lon, lat, alt, vn, ve, vd, eph, epv]
    return out


def _same(a: Tracker, b: Tracker, b_updated: dict[str, object]) -> None:
    assert a.counters == b.counters
    assert a.tracks() == b.tracks()
    for tid in a.tracks():
        assert np.array_equal(a.covariance(tid), b.covariance(tid))
    assert {t.id: t for t in a.take_updated()} == b_updated


@settings(max_examples=60, deadline=None)
@given(batches=st.lists(st.lists(_entry, max_size=16), min_size=1, max_size=5))
def test_lane_entries_are_ingested_exactly_as_their_measurements(
    batches: list[list[Entry]],
) -> None:
    lane = _lane()
    cfg = {"stale_after_s": 1.0, "gate_reset_count": 1}
    by_measurement = new_tracker(**cfg)  # Measurements, the C round when built
    by_lane = new_tracker(**cfg)  # lane entries, checked in C when built
    by_lane_numpy = new_tracker(**cfg)  # lane entries, checked in NumPy, NumPy rounds
    by_measurement_numpy = new_tracker(**cfg)  # Measurements, NumPy rounds only
    for k, entries in enumerate(batches):
        values = _values(entries, T0 + 3.0 * k)
        ms: list[Measurement] = [
            lane.measurement(values, at) for at in range(0, len(values), LANE_STRIDE)
        ]
        want = by_measurement.ingest(ms)
        assert by_lane.ingest([], values, lane.sources) == want
        with _no_c():
            assert by_lane_numpy.ingest([], values, lane.sources) == want
            assert by_measurement_numpy.ingest(ms) == want
        updated: dict[str, object] = {t.id: t for t in by_measurement.take_updated()}
        _same(by_lane, by_measurement, updated)
        _same(by_lane_numpy, by_measurement, updated)
        _same(by_measurement_numpy, by_measurement, updated)


def test_a_batch_of_measurements_and_lane_entries_is_one_batch() -> None:
    """Lane entries and Measurements of one track in one call are sorted together by capture
    time: the later ones are not rejected as out of order."""
    lane = _lane()
    values = _values([(2, 0, 0.0, 0.0, 100.0, (1.0, 0.0, 0.0), NAN, NAN, "")], T0)
    late = _values([(2, 5, 2.0, 0.0, 100.0, (1.0, 0.0, 0.0), NAN, NAN, "")], T0)
    tr = new_tracker()
    stats = tr.ingest([lane.measurement(late, 0)], values, lane.sources)
    assert (stats.accepted, stats.out_of_order, len(stats.new_intruders)) == (2, 0, 1)


@pytest.mark.skipif(not C_BUILT, reason="the C extension _kalman_c is not built here")
@settings(max_examples=40, deadline=None)
@given(
    m=st.integers(1, 40),
    dt=st.floats(0.0, 3.0),
    r=st.floats(0.0, 30.0),
    with_vel=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_c_round_equals_the_numpy_round_bit_for_bit(
    m: int, dt: float, r: float, with_vel: bool, seed: int
) -> None:
    """update_rows against the NumPy round (kalman.step) on random states, including a zero
    measurement variance."""
    rng = np.random.default_rng(seed)

    def tracker() -> Tracker:
        tr = new_tracker()
        rng2 = np.random.default_rng(seed)
        tr._grow(m)
        tr._n = m
        tr._ids = [f"sysid:{i}" for i in range(m)]  # type: ignore[misc]
        tr._x[:m] = rng2.normal(size=(m, 3, 2)) * 2.0  # within the gate of every measurement
        p = np.abs(rng2.normal(size=(m, 3, 3))) + 0.1
        p[:, :, 1] = 0.01  # pv small: a positive definite block
        tr._p[:m] = p
        tr._t[:m] = T0
        return tr

    a = np.zeros((NCOL, m))
    a[0] = T0 + dt
    a[1:4] = rng.normal(size=(3, m)) * 0.5
    a[4:7] = rng.normal(size=(3, m))
    a[7:10] = r
    a[10:13] = 0.25
    a[14] = 1.0 if with_vel else 0.0
    rw = rng.permutation(m).astype(np.intp)
    c_tr, np_tr = tracker(), tracker()
    got = c_tr._round_plain(rw, a.copy())
    assert got == (m, 0, 0, 0, 0, 0)  # the C kernel took the round
    with _no_c():
        assert np_tr._round_plain(rw, a.copy()) is None  # without it the NumPy round runs
        want = np_tr._round(rw, a.copy(), None, with_vel)
    assert got == want
    assert np.array_equal(c_tr._x, np_tr._x) and np.array_equal(c_tr._p, np_tr._p)
    assert np.array_equal(c_tr._t, np_tr._t) and np.array_equal(c_tr._src_t, np_tr._src_t)
    assert np.array_equal(c_tr._updates, np_tr._updates)
    assert c_tr.take_updated() == np_tr.take_updated()


def test_the_c_kernel_was_built_from_these_layouts() -> None:
    """The C kernel's copy of the record and entry layouts is layout.py's (kernel.py refuses
    a build that differs at import)."""
    if not C_BUILT:
        pytest.skip("the C extension _kalman_c is not built here")
    assert kernel._c is not None
    assert tuple(kernel._c.LAYOUT) == C_LAYOUT


@pytest.mark.skipif(not C_BUILT, reason="the C extension _kalman_c is not built here")
def test_the_c_kernel_refuses_arrays_it_was_not_made_for() -> None:
    """Bad arrays get one clear error naming the argument, and nothing is written."""
    c = kernel._c
    assert c is not None
    tr = new_tracker()
    lane = _lane()
    tr.ingest(
        [], _values([(0, 0, 0.0, 0.0, 100.0, (0.0, 0.0, 0.0), NAN, NAN, "")], T0), lane.sources
    )
    x0 = tr._x.copy()
    args = (tr._x, tr._p, tr._t, tr._src_t, tr._updates, tr._gate_fails, tr._stale)
    a = np.zeros((15, 1))
    a[0] = T0 + 1.0
    q, limits = (1.0, 1.0, 1.0), (1.0, 1.0, 1.0, 5.0)  # max_jump, margin, max_speed, restart
    with pytest.raises(ValueError, match="rw"):
        c.update_rows(np.zeros(1, dtype=np.int32), a, *args, q, *limits)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="a has"):
        c.update_rows(np.zeros(1, dtype=np.intp), a[:5], *args, q, *limits)
    with pytest.raises(IndexError, match="row 1000"):
        c.update_rows(np.array([1000], dtype=np.intp), a, *args, q, *limits)
    assert np.array_equal(tr._x, x0)
    dflt = ((1.0, 1.0, 1.0),) * 3
    with pytest.raises(ValueError, match="whole number"):
        c.entry_records([1.0] * 12, np.zeros((15, 1)), np.zeros(1, dtype=np.intp),
                        dflt, 0.1, 1.0, 1.0, (0.0, 1.0), 0.0, 1.0)  # fmt: skip
    with pytest.raises(TypeError):
        c.entry_records(["x"] * 11, np.zeros((15, 1)), np.zeros(1, dtype=np.intp),
                        dflt, 0.1, 1.0, 1.0, (0.0, 1.0), 0.0, 1.0)  # fmt: skip
    one = [0, T0, T0, 0.0, 0.0, 100.0, 0.0, 0.0, 0.0, NAN, NAN]
    with pytest.raises(ValueError, match="source kind 3"):
        c.entry_records(one, np.zeros((15, 1)), np.zeros(1, dtype=np.intp), dflt, 0.1, 1.0,
                        1.0, (0.0, 1.0), 0.0, 1e4, np.array([3], dtype=np.intp))  # fmt: skip
    with pytest.raises(ValueError, match="kinds"):
        c.entry_records(one, np.zeros((15, 1)), np.zeros(1, dtype=np.intp), dflt, 0.1, 1.0,
                        1.0, (0.0, 1.0), 0.0, 1e4, np.array([0], dtype=np.int8))  # fmt: skip


def test_the_c_kernel_is_built_where_it_is_required() -> None:
    """CI sets GCS_UTM_REQUIRE_C: there the build must not silently fall back to Python."""
    if not os.environ.get("GCS_UTM_REQUIRE_C"):
        pytest.skip("GCS_UTM_REQUIRE_C is not set (only CI requires the C extension)")
    assert C_BUILT, "gcs_utm.core.tracking._kalman_c was not built (no C compiler?)"


# one Measurement: (source, sys id or ICAO, step, east, alt, velocity or None, eph, epv)
_meas = st.tuples(
    st.sampled_from(list(MeasurementSource)),
    st.integers(0, 3),
    st.integers(0, 5),
    st.floats(-40.0, 40.0),
    st.sampled_from([100.0, 100.0, -2_000.0, NAN]),
    st.one_of(
        st.none(),
        st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-4, 4)),
        st.just((500.0, 0.0, 0.0)),
        st.just((NAN, 0.0, 0.0)),
    ),
    st.sampled_from([None, None, 0.3, 4.0, -1.0, INF, NAN]),
    st.sampled_from([None, None, 0.2, 6.0]),
)


MItem = tuple[MeasurementSource, int, int, float, float, object, object, object]


def _measurement(t0: float, item: MItem) -> Measurement:
    source, who, step, east, alt, vel, eph, epv = item
    lat, lon = FRAME.point_to_wgs84(east + 100.0 * who, 0.5 * east)
    t = t0 + 0.4 * step
    adsb = source is MeasurementSource.ADSB
    return Measurement(
        source=source,
        capture_t_s=t,
        receipt_t_s=t + 0.05,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=alt,
        vel_ned_mps=vel,  # type: ignore[arg-type]
        eph_m=eph,  # type: ignore[arg-type]
        epv_m=epv,  # type: ignore[arg-type]
        sys_id=None if adsb else SysId(who + 1),
        icao24=Icao24(f"a0000{who}") if adsb else None,
    )


@pytest.mark.skipif(not C_BUILT, reason="the C extension _kalman_c is not built here")
@settings(max_examples=60, deadline=None)
@given(batches=st.lists(st.lists(_meas, max_size=12), min_size=1, max_size=4))
def test_measurements_of_every_source_are_checked_alike_in_c_and_numpy(
    batches: list[list[MItem]],
) -> None:
    """Telemetry, ADS-B and MQTT, with and without a velocity, known, unknown and bad
    accuracies: the C checks and records give the NumPy reference's counts and states."""
    c_tr = new_tracker(stale_after_s=1.0, gate_reset_count=1)
    np_tr = new_tracker(stale_after_s=1.0, gate_reset_count=1)
    for k, items in enumerate(batches):
        ms = [_measurement(T0 + 3.0 * k, item) for item in items]
        want = c_tr.ingest(ms)
        with _no_c():
            assert np_tr.ingest(ms) == want
        _same(c_tr, np_tr, {t.id: t for t in np_tr.take_updated()})
