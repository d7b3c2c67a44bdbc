"""Consecutive service cycles (``Tracker.snapshot`` -> ``Monitor.cycle``) in a process that
keeps the memory it frees, as the service does (``gcs_utm.app.memory``): each cycle's arrays
are the pages of the one before, so nothing of an earlier, larger airspace may show in a
later one. The threats after a sequence of cycles must be those a fresh Monitor finds on the
last airspace alone."""

from __future__ import annotations

import numpy as np

from gcs_utm.app.memory import retain_freed_memory
from gcs_utm.bench.monitoring import _FRAME, _T0, _fences, _traffic
from gcs_utm.core.monitoring import Monitor, MonitoringConfig
from gcs_utm.core.tracking import Tracker, TrackingConfig
from gcs_utm.model import AirspaceSnapshot, Geofence, Measurement, Operation, Threat

_BOX_M = 6000.0  # dense: hundreds of losses and geofence conflicts among 3,000 UAS


def _tracker(ops: list[Operation], meas: list[Measurement]) -> Tracker:
    tr = Tracker(_FRAME, TrackingConfig())
    tr.set_operations(ops)
    tr.ingest(meas[0::2])
    tr.ingest(meas[1::2])
    return tr


def _snapshot(tr: Tracker, ops: list[Operation], fences: list[Geofence]) -> AirspaceSnapshot:
    tracks, prediction = tr.snapshot(_T0)
    return AirspaceSnapshot(
        t_s=_T0,
        operations={o.id: o for o in ops},
        tracks=tracks,
        geofences=tuple(fences),
        prediction=prediction,
    )


def _figures(threats: list[Threat]) -> set[tuple[object, ...]]:
    """What a threat says, without its id and times of detection."""
    return {
        (
            t.kind,
            t.uas_ids,
            t.geofence_id,
            t.predicted_event_at_s,
            t.closest_approach_t_s,
            t.closest_approach_m,
            t.horizontal_m,
            t.vertical_m,
            t.message,
        )
        for t in threats
    }


def test_cycles_after_a_larger_airspace_give_the_threats_of_a_fresh_monitor() -> None:
    retain_freed_memory()
    rng = np.random.default_rng(5)
    fences = _fences(rng, _BOX_M, 12)
    ops, meas = _traffic(3000, rng, _BOX_M)
    cfg = MonitoringConfig()
    large = _snapshot(_tracker(ops, meas), ops, fences)
    # The first 1,000 UAS of the same traffic, in a tracker of their own (N shrinks).
    small_tracker = _tracker(ops[:1000], meas[:2000])
    reused = Monitor(_FRAME, cfg)
    for _ in range(cfg.open_cycles + 1):
        reused.cycle(large)
    for _ in range(cfg.open_cycles + 1):
        reused.cycle(_snapshot(small_tracker, ops[:1000], fences))
    fresh = Monitor(_FRAME, cfg)
    for _ in range(cfg.open_cycles + 1):
        fresh.cycle(_snapshot(small_tracker, ops[:1000], fences))
    alone = Monitor(_FRAME, cfg)
    for _ in range(cfg.open_cycles + 1):
        alone.cycle(large)
    # Some threats of the larger airspace involve UAS not in the smaller one: they must go.
    assert len(alone.active()) > len(fresh.active()) > 50
    assert _figures(reused.active()) == _figures(fresh.active())
