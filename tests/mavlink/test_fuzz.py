"""A seeded fuzz of the hub's receive path (issue 21): a few hundred thousand mutated and
spoofed datagrams and stream chunks (gcs_utm/bench/fuzz.py; ``gcs-utm bench fuzz`` for
longer runs). Nothing escapes the receive callback, no handler fails, every datagram moves a
counter, every kind of bad frame is counted under its cause, per-sender state stays within
its caps and memory within a bound; the same seed gives the same counts."""

from __future__ import annotations

import logging

import pytest

from gcs_utm.bench.fuzz import fuzz

pytestmark = pytest.mark.timeout(300)

FRAMES = 250_000
CAP = 256


async def test_fuzzed_frames_are_survived_counted_and_bounded(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING):
        r = await fuzz(FRAMES, seed=7, max_senders=CAP, max_vehicles=CAP)
    assert r.datagrams + r.stream_chunks == FRAMES
    assert r.handler_errors == 0
    assert r.uncounted == 0, "a datagram was dropped without any counter moving"
    # every cause is exercised, and counted under its own name
    assert all(n > 0 for n in r.dropped.values()), r.dropped
    # frames of the legitimate vehicles still get through
    assert r.sink["measurements"] > 1000 and r.sink["vehicles"] >= 6
    # bounded: per link and per hub, whatever the number of identities seen
    assert r.senders_held <= 2 * CAP and r.vehicles_held <= CAP
    assert r.senders_evicted > 10 * CAP
    assert r.rss_end_mb - r.rss_start_mb < 40.0, r
    # rate-limited: a quarter of a million bad frames make a handful of warning lines
    assert len(caplog.records) < 200, len(caplog.records)


async def test_the_same_seed_gives_the_same_counts() -> None:
    a = await fuzz(5000, seed=3)
    b = await fuzz(5000, seed=3)
    assert (a.dropped, a.frames_decoded, a.sink) == (b.dropped, b.frames_decoded, b.sink)
