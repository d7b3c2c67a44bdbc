"""A short soak (``gcs-utm bench soak``) of serve's services in fast time: operations come
and go, threats are raised and decided, and what the services hold stays flat."""

from __future__ import annotations

from pathlib import Path

from gcs_utm.bench.soak import Traffic, soak

# what the services hold per operation, geofence or threat: bounded by what is current
PER_OPERATION = (
    "airspace._operations",
    "airspace._geofences",
    "tracker._ids",
    "usm.threats",
    "usm.threat_closer._watched",
    "emergency.em._cases",
    "emergency.em._recs",
    "plan_history",
    "filing.conflicts",
    "filing.fence_findings",
    "filing._state",
    "td._plans",
)


def test_a_short_soak_holds_flat(tmp_path: Path) -> None:
    traffic = Traffic(
        hours=0.4,
        every_s=20.0,
        flight_s=90.0,
        conflict_every=3,
        sample_s=240.0,
        keep_s=60.0,
        top=100_000,  # every type: one outside the top would read as 0
    )
    *samples, summary = soak(traffic, tmp_path / "soak.sqlite")
    assert summary["benchmark"] == "soak.summary" and len(samples) == 6
    rows = [s["store"]["rows_by_table"] for s in samples]
    assert rows[-1]["operations"] >= 70  # traffic came and went ...
    assert rows[-1]["threats"] > rows[1]["threats"] > 0  # ... and met
    steady, last = samples[2]["containers"], samples[-1]["containers"]
    for name in PER_OPERATION:
        assert last.get(name, 0) <= steady.get(name, 0) + 6, (name, steady, last)
    assert last["airspace._operations"] <= 15  # of 72 filed
    # Monitoring's projections are pruned once they hold twice what is current (+ 16): they
    # saw-tooth under that bound (at most 15 operations current, 72 filed) instead of
    # following the operations one by one
    for sample in samples[2:]:
        for cache in ("_plan_cache", "_fence_cache"):
            held_now = sample["containers"].get(f"monitoring.monitor.{cache}", 0)
            assert held_now <= 2 * 15 + 16 + 1, (cache, sample["containers"])
    held = [s["objects_grown_since_first"].get("Operation", 0) for s in samples[2:]]
    # Operation objects: what is current comes and goes, what ended does not pile up
    assert max(held[1:]) <= held[0] + 6, held
    assert samples[-1]["tasks"] <= samples[2]["tasks"] + 6
    assert samples[-1]["sockets"] == samples[0]["sockets"]
