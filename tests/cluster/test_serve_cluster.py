"""Two ``gcs-utm serve --cluster`` processes on one PostgreSQL database: each holds its
region; after ``kill -9`` of one, the other takes its region over and resumes its operations
and its pending recommendation (proposed again as the next version in the survivor's life)
within the failover bound; a clean stop releases the leases."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from gcs_utm.cluster import lease
from gcs_utm.model import RecommendationState
from gcs_utm.scenario import load_scenario
from gcs_utm.store import open_store
from tests.store.conftest import raw_execute
from tests.store.test_store import UC1, _rec

REPO = Path(__file__).resolve().parents[2]
LEASE_S, RENEW_S = 2.0, 0.5


def _config(path: Path, url: str, instance: str, region: str, standby: bool) -> Path:
    sc = load_scenario(UC1)
    (e1, _), (e2, _) = (
        sc.frame.point_to_local(op.plan.waypoints[0].lat_deg, op.plan.waypoints[0].lon_deg)
        for op in sc.operations
    )
    border_m = (e1 + e2) / 2  # UAS1 departs west of it (c0r0), UAS2 east (c1r0)
    path.write_text(
        f"""
[airspace]
origin_lat_deg = {sc.frame.origin_lat_deg}
origin_lon_deg = {sc.frame.origin_lon_deg}
ground_elevation_amsl_m = {sc.frame.ground_elevation_amsl_m}
[mavlink]
links = ["udpin:127.0.0.1:0"]
[store]
url = "{url}"
[cluster]
instance = "{instance}"
region = "{region}"
standby = {str(standby).lower()}
west_m = {border_m - 2000.0}
south_m = -5000.0
cell_m = 2000.0
columns = 2
rows = 1
halo_m = 200.0
lease_s = {LEASE_S}
renew_s = {RENEW_S}
"""
    )
    return path


def _serve(config: Path, log: Path) -> subprocess.Popen[bytes]:
    with open(log, "wb") as out:
        return subprocess.Popen(
            [
                sys.executable,
                "-m",
                "gcs_utm",
                "serve",
                "--cluster",
                "--headless",
                "--config",
                str(config),
            ],
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONPATH": str(REPO)},
        )


def _wait(cond: object, timeout_s: float, what: str) -> float:
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if cond():  # type: ignore[operator]
            return time.monotonic() - start
        time.sleep(0.05)
    raise AssertionError(f"not within {timeout_s} s: {what}")


@pytest.mark.timeout(90)
def test_kill_9_of_an_owner_hands_its_region_and_prompt_to_the_survivor(
    pg_url: str, tmp_path: Path
) -> None:
    sc = load_scenario(UC1)
    rec = replace(_rec(), deadline_t_s=time.time() + 3600.0)  # UAS1's prompt, still open
    with open_store(pg_url) as earlier:  # an earlier life of A filed the airspace
        earlier.begin_life()
        for op in sc.operations:
            earlier.save_operation(op)
        earlier.save_recommendation(rec)
    a = _serve(_config(tmp_path / "a.toml", pg_url, "A", "c0r0", False), tmp_path / "a.log")
    b = _serve(_config(tmp_path / "b.toml", pg_url, "B", "c1r0", True), tmp_path / "b.log")
    procs = [a, b]
    try:

        def holders() -> dict[str, str]:
            with open_store(pg_url) as s:
                return {r: h.split("#")[0] for r, h in lease.owners(s).items()}

        _wait(lambda: holders() == {"c0r0": "A", "c1r0": "B"}, 30.0, "A and B hold their regions")
        # A resumed its own region's pending prompt as v2 in its life
        _wait(lambda: _versions(pg_url) == [1, 2], 10.0, "A re-proposes the prompt")
        time.sleep(2 * LEASE_S)
        assert holders() == {"c0r0": "A", "c1r0": "B"}  # no takeover while A lives
        killed = time.monotonic()
        a.send_signal(signal.SIGKILL)
        a.wait(10)
        _wait(lambda: holders().get("c0r0") == "B", 10.0, "B takes c0r0 over")
        failover_s = time.monotonic() - killed
        assert failover_s <= LEASE_S + RENEW_S + 2.0, failover_s
        _wait(lambda: _versions(pg_url) == [1, 2, 3], 10.0, "B re-proposes the prompt")

        def gained_by_b() -> bool:  # recorded after the re-proposal, in a later writer batch
            with open_store(pg_url) as s:
                return any(
                    e.action == "region_gained" and e.subject == "c0r0" and e.actor[0] == "B"
                    for e in s.load_audit()
                )

        _wait(gained_by_b, 10.0, "B records the region it gained")
        with open_store(pg_url) as s:
            latest = s.load_recommendations()
            assert [(r.id, r.version, r.state) for r in latest] == [
                (rec.id, 3, RecommendationState.PROPOSED)
            ]
            assert "resumed by B#" in latest[0].reason
            assert latest[0].deadline_t_s == rec.deadline_t_s
            gained = [e for e in s.load_audit() if e.action == "region_gained"]
        by = {(e.actor.split("#")[0], e.subject): e for e in gained}
        assert set(by) == {("A", "c0r0"), ("B", "c1r0"), ("B", "c0r0")}
        assert by[("B", "c0r0")].detail["operations"] == ["UAS1"]
        assert by[("B", "c0r0")].detail["pending"] == [f"{rec.id} v2"]
        assert by[("B", "c1r0")].detail["operations"] == ["UAS2"]
        # rows: v1 by the earlier life, v2 by A, v3 by B: three lives, nothing overwritten
        epochs = raw_execute(pg_url, "SELECT version, epoch FROM recommendations ORDER BY 1")
        assert len({e for _v, e in epochs}) == 3
        b.send_signal(signal.SIGTERM)
        assert b.wait(20) == 0
        assert holders() == {}  # B released its leases on the way out
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(10)


def _versions(url: str) -> list[int]:
    rows = raw_execute(url, "SELECT version FROM recommendations ORDER BY version")
    return [int(v) for (v,) in rows]  # type: ignore[call-overload]


def test_cluster_needs_a_postgresql_store_and_a_sane_lease(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from gcs_utm.cli import main

    assert main(["serve", "--cluster", "--headless", "--db", str(tmp_path / "x.sqlite")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "serve --cluster" in err and "postgresql://" in err
    bad = tmp_path / "bad.toml"
    bad.write_text("[cluster]\nlease_s = 1.0\nrenew_s = 0.8\n")
    assert main(["config", "check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "cluster.renew_s" in err and "half of lease_s" in err
    bad.write_text('[cluster]\nregion = "c5r0"\n[store]\nurl = "postgresql://x@/y?host=/none"\n')
    assert main(["serve", "--cluster", "--headless", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "c5r0" in err and "outside the 2x2 grid" in err
    bad.write_text('[cluster]\nregion = "c1r1"\n[store]\nurl = "postgresql://x@/y?host=/none"\n')
    assert main(["serve", "--cluster", "--headless", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot connect" in err and "/none" in err
