"""Snapshot tracks as columns (issue 24): ``TrackMap`` builds a ``Track`` only for a row that
is read and gives the same objects as building them all; its columns are a copy (a later
ingest changes nothing); Monitoring gives the same threats from the columns as from Track
objects."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from test_snapshot import _random_airspace
from tracking_helpers import FRAME, meas

from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.tracking.tracks import TrackColumns, TrackMap, track_columns
from gcs_utm.model import AirspaceSnapshot, Threat, TrackId


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), ahead=st.floats(-3.0, 30.0))
def test_rows_read_one_by_one_equal_the_full_build(seed: int, ahead: float) -> None:
    tr, t_end = _random_airspace(seed)
    lazy, _ = tr.snapshot(t_end + ahead)
    full, _ = tr.snapshot(t_end + ahead)
    assert isinstance(lazy, TrackMap)
    ids = list(lazy)  # iterating the ids builds nothing
    assert lazy._all is None and lazy._one == {}
    for tid in reversed(ids):
        assert tid in lazy
        assert lazy[tid] == full.materialise()[tid]
        assert lazy.get(tid) is lazy[tid]  # built once
    assert lazy._all is None
    assert lazy == full and len(lazy) == len(ids)
    assert lazy.get(TrackId("nobody")) is None and TrackId("nobody") not in lazy
    with pytest.raises(KeyError):
        lazy[TrackId("nobody")]
    # Columns converted back from the objects are the same columns.
    back = TrackColumns.of_tracks(full.materialise(), FRAME)
    cols = lazy.columns
    assert back.ids == cols.ids and back.operation_ids == cols.operation_ids
    for name in ("t_s", "pos", "vel", "position_sigma_m", "cooperative", "stale", "updates"):
        assert np.array_equal(getattr(back, name), getattr(cols, name)), name
    assert np.array_equal(back.next_waypoint, cols.next_waypoint)


def test_a_snapshot_does_not_change_with_later_measurements() -> None:
    tr, t_end = _random_airspace(5)
    lazy, _ = tr.snapshot(t_end)
    before = dict(tr.snapshot(t_end)[0].items())
    tr.ingest([meas(9000.0, 9000.0, 100.0, t_end + 0.5, sys_id=99)])
    tr.ingest([meas(1.0, 2.0, 100.0, t_end + 0.6, sys_id=10)])
    tr.check_stale(t_end + 100.0)
    assert dict(lazy.items()) == before


def _figures(t: Threat) -> tuple[object, ...]:
    """Every field of a threat but the prediction it carries (compared by identity)."""
    return tuple(getattr(t, f.name) for f in dataclasses.fields(t) if f.name != "snapshot")


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_monitoring_reads_the_same_from_columns_and_from_objects(seed: int) -> None:
    _compare_monitors(seed)


def test_the_comparison_sees_threats() -> None:
    assert _compare_monitors(0) > 0


def _compare_monitors(seed: int) -> int:
    """Two monitors, one on the snapshot's columns, one on Track objects: same threats
    over three cycles. Returns how many threats were reported."""
    tr, t_end = _random_airspace(seed, intruders=seed % 2 == 0)
    ops = dict(tr._intake.ops)
    cfg = MonitoringConfig(separation_horizontal_m=400.0, separation_vertical_m=100.0)
    on_columns = Monitor(FRAME, cfg)
    on_objects = Monitor(FRAME, cfg)
    seen = 0
    for k in range(3):
        t_s = t_end + 2.0 * k
        tracks, pred = tr.snapshot(t_s)
        objects = dict(tr.snapshot(t_s)[0].items())
        a = on_columns.cycle(
            AirspaceSnapshot(t_s=t_s, operations=ops, tracks=tracks, geofences=(), prediction=pred)
        )
        b = on_objects.cycle(
            AirspaceSnapshot(t_s=t_s, operations=ops, tracks=objects, geofences=(), prediction=pred)
        )
        assert [_figures(x) for x in a] == [_figures(x) for x in b]
        assert all(x.snapshot is pred for x in a + b)
        seen += len(a)
        assert isinstance(tracks, TrackMap) and tracks._all is None  # no object was built
    assert [_figures(x) for x in on_columns.active()] == [_figures(x) for x in on_objects.active()]
    assert track_columns(objects, FRAME).ids == tuple(objects)
    return seen
