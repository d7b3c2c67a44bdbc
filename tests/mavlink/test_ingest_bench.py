"""The ingest benchmark's datagram-to-track paths really update tracks (small sizes)."""

from __future__ import annotations

import asyncio

from gcs_utm.bench import ingest


def test_inprocess_tracked_updates_one_track_per_vehicle() -> None:
    ms = ingest._inprocess(2_000, 100, 1, True, tracker_batch=500)
    assert len(ms) == 1 and ms[0] > 0.0


def test_socket_tracked_feeds_every_delivered_measurement_to_the_tracker() -> None:
    r = asyncio.run(ingest._one(2_000, 100, 5_000.0, tracked=True))
    assert r.sent == 2_000
    assert r.sink.n > 0
    assert r.sink.updated == r.sink.n  # every delivered measurement updated a track
