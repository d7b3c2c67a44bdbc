"""``Tracker.predict`` works in blocks of rows (``PREDICT_BLOCK_ROWS``) so that a block's
temporaries stay in the CPU cache: the result must be the one-block result bit for bit,
whatever the block size and whichever kind of row (plan-following, extrapolated, intruder)
is the majority of a block."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from tracking_helpers import T0, meas, new_tracker, operation, plan_from_local

from gcs_utm.core.tracking import tracker as tracker_module
from gcs_utm.core.tracking.tracker import Tracker
from gcs_utm.model import Measurement

_TURN = [(0, 0, 100, 0.0), (100, 0, 100, 10.0), (100, 100, 100, 20.0), (0, 100, 100, 30.0)]


def _mixed_fleet() -> Tracker:
    """Sixty tracks in runs of uneven kinds: on their plan (5 m off track), 200 m off it
    (extrapolated), and ADS-B intruders; six seconds of measurements each."""
    kinds = ["on"] * 9 + ["off"] * 6 + ["intruder"] * 4 + ["on", "off", "intruder"] * 3
    kinds = (kinds * 3)[:60]
    ops = []
    for i, kind in enumerate(kinds):
        if kind != "intruder":
            wps = [(e + 1000.0 * i, n, a, T0 + t) for e, n, a, t in _TURN]
            ops.append(operation(f"op{i}", plan_from_local(f"op{i}", wps), sys_id=i + 1))
    tr = new_tracker()
    tr.set_operations(ops)
    for k in range(6):
        batch: list[Measurement] = []
        for i, kind in enumerate(kinds):
            east = 1000.0 * i + 10.0 * k
            if kind == "intruder":
                batch.append(meas(east, 50.0, 300, T0 + k, sys_id=None, icao24=f"{i:06x}"))
            else:
                north = 5.0 if kind == "on" else -200.0
                batch.append(meas(east, north, 100, T0 + k, sys_id=i + 1, eph_m=0.5))
        tr.ingest(batch)
    return tr


@pytest.mark.parametrize("t_s", [T0 + 2.5, T0 + 5.0, T0 + 40.0])
def test_prediction_in_blocks_equals_one_block_bit_for_bit(
    monkeypatch: pytest.MonkeyPatch, t_s: float
) -> None:
    tr = _mixed_fleet()
    assert len(tr) == 60
    monkeypatch.setattr(tracker_module, "PREDICT_BLOCK_ROWS", 1 << 30)
    whole = tr.predict(t_s)
    for rows in (1, 4, 7, 16, 59):
        monkeypatch.setattr(tracker_module, "PREDICT_BLOCK_ROWS", rows)
        blocks = tr.predict(t_s)
        assert blocks.track_ids == whole.track_ids
        assert blocks.points.shape == whole.points.shape
        assert blocks.points.tobytes() == whole.points.tobytes()
        assert blocks.sigma_m.tobytes() == whole.sigma_m.tobytes()


def test_the_mixed_fleet_has_every_kind_of_row() -> None:
    """The fleet above exercises both branches of a block: rows on their plan follow it
    to its end at north = 100 m), rows 200 m off are extrapolated (east at 10 m/s, north
    held at -200 m)."""
    tr = _mixed_fleet()
    pred = tr.predict(T0 + 5.0)
    north_end = pred.points[:, -1, 1]
    on = [i for i, t in enumerate(pred.track_ids) if str(t).startswith("op")]
    follows = np.abs(north_end[on] - 100.0) < 10.0
    assert follows.any() and not follows.all()
    assert np.all(np.abs(north_end[on][~follows] + 200.0) < 10.0)
    assert any(str(t).startswith("icao:") for t in pred.track_ids)
