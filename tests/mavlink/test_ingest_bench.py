"""The ingest benchmark's datagram-to-track paths really update tracks (small sizes), through
the app's receive path (hub -> USM -> tracking service -> tracker)."""

from __future__ import annotations

import asyncio

from gcs_utm.bench import ingest


def test_inprocess_tracked_updates_one_track_per_vehicle() -> None:
    # 600 vehicles from 3 addresses: system ids 1..250 repeat, the tracks must not merge
    # (_inprocess raises unless every measurement updated a track and there is one per vehicle)
    ms = ingest._inprocess(2_400, 600, 1, True, tracker_batch=500)
    assert len(ms) == 1 and ms[0] > 0.0


def test_socket_tracked_feeds_every_delivered_measurement_to_a_track_per_vehicle() -> None:
    r = asyncio.run(ingest._one(2_400, 600, 5_000.0, tracked=True))
    assert r.sent == 2_400
    assert r.received > 0
    assert r.updated == r.received  # every delivered measurement updated a track
    assert r.tracks == 600  # vehicles sharing a system id on other addresses stay apart
