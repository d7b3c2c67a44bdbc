"""Replay and live share one pipeline: a fast-time ``run --record`` of use case 1 (built-in
vehicles, loopback UDP) replayed with ``gcs-utm replay DIR --scenario ... --scenario-t0 ...``
gives the live run's tracks (the same ids, last positions and update times) and Monitoring's
threats (the same kinds for the same UAS, detected at the same time within one monitoring
period: the replay's cycles start at the first record, the live service's when it started).

The replay decodes the recorded packets with the live hub at their recorded receipt times, so
its measurements are the live ones: measured, the same updates, 0 m and 0 s apart; the loss of
separation detected 0.25 s apart."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import pytest

from gcs_utm.app import (
    FAST_TIME_EPOCH_UTC_S,
    OperatorMode,
    RunOptions,
    Runtime,
    run_scenario_blocking,
)
from gcs_utm.cli import main
from gcs_utm.geo import haversine_m
from gcs_utm.model import ThreatKind
from gcs_utm.settings import Settings

SCENARIO = Path(__file__).resolve().parents[2] / "config" / "scenarios" / "use_case_1.toml"
LEAD_S = 10.0
DURATION_S = 125.0  # the loss of separation is predicted about 110 s after t0
MONITORING = {  # the kinds Monitoring raises (the others come from vehicle hazards)
    ThreatKind.LOSS_OF_SEPARATION,
    ThreatKind.GEOFENCE_INTRUSION,
    ThreatKind.GEOFENCE_CONFLICT,
    ThreatKind.UAS_OUT_OV,
    ThreatKind.UAS_IN_CV,
    ThreatKind.INTRUDER,
}


def _record(tmp_path: Path) -> Runtime:
    seen: list[Runtime] = []

    async def on_runtime(rt: Runtime) -> None:
        seen.append(rt)

    options = RunOptions(
        speed=math.inf,
        headless=True,
        quiet=True,
        operator=OperatorMode.AUTO_REJECT,  # the filed plans stay: the replay has only them
        out_dir=tmp_path / "run",
        figures=False,
        lead_s=LEAD_S,
        duration_s=DURATION_S,
        record_dir=tmp_path / "rec",
    )
    run_scenario_blocking(SCENARIO, Settings(), options, on_runtime=on_runtime)
    return seen[0]


def _live_threats(rt: Runtime) -> list[tuple[str, tuple[str, ...], float]]:
    first: dict[str, Any] = {}
    for t in rt.usm.threat_log:
        if t.kind in MONITORING:
            first.setdefault(t.id, t)
    return sorted((t.kind.value, tuple(sorted(t.uas_ids)), t.detected_at_s) for t in first.values())


def test_replayed_record_of_a_run_gives_its_tracks_and_threats(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rt = _record(tmp_path)
    live_tracks = rt.tracking.tracker.tracks()
    live_threats = _live_threats(rt)
    assert {k for k, _, _ in live_threats} >= {"LOSS_OF_SEPARATION"}, live_threats

    out = tmp_path / "replay.json"
    t0 = str(FAST_TIME_EPOCH_UTC_S + LEAD_S)
    args = ["replay", str(tmp_path / "rec"), "--scenario", str(SCENARIO)]
    assert main([*args, "--scenario-t0", t0, "--report", str(out), "--no-progress"]) == 0
    assert "2 tracks" in capsys.readouterr().out
    report = json.loads(out.read_text())

    assert set(report["tracks"]) == set(live_tracks) == {"UAS1", "UAS2"}
    for tid, live in live_tracks.items():
        got = report["tracks"][tid]
        pos = got["last_position"]
        error_m = haversine_m(pos["lat_deg"], pos["lon_deg"], live.lat_deg, live.lon_deg)
        assert error_m < 0.01, (tid, error_m)
        assert pos["alt_amsl_m"] == pytest.approx(live.alt_amsl_m, abs=0.01)
        assert got["last_t_s"] == pytest.approx(live.t_s, abs=1e-3)
        assert (got["updates"], got["cooperative"]) == (live.updates, True)
    replayed = sorted(
        (t["kind"], tuple(sorted(t["uas"])), t["first_t_s"]) for t in report["threats"]
    )
    assert [(k, u) for k, u, _ in replayed] == [(k, u) for k, u, _ in live_threats]
    period_s = Settings().monitoring.period_s
    for (_, _, got_s), (_, _, want_s) in zip(replayed, live_threats, strict=True):
        assert got_s == pytest.approx(want_s, abs=period_s + 0.01)


def test_replay_as_fast_as_possible_refuses_an_ordinary_loop() -> None:
    from gcs_utm.app.replay import ReplayConfig, replay

    async def main_() -> None:
        await replay(ReplayConfig(), iter([(1.0, b"")]))

    with pytest.raises(RuntimeError, match="FastTimeLoop"):
        asyncio.run(main_())
