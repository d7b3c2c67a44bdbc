"""Issue 18's acceptance: two real PX4 quadrotors on crossing missions stay apart.

The pilots' own GCS (tests/autopilot/pilot.py, on PX4's API link) uploads each operator's
mission and starts it; ``gcs-utm serve --headless --auto-accept`` holds the GCS link (14550),
files the vehicles' operations, predicts the loss of separation, uploads a resolution PX4
accepts and verifies, and PX4 flies it. The flown separation is measured from PX4's own
positions on the API link, not from gcs-utm's tracks.
"""

from __future__ import annotations

import json
import math
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.pilot import PilotLink, Sample, local_m, mission_items, offset_deg

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; serve --speed matches it
LEG_M = 220.0  # each UAS starts this far from the crossing point and ends as far beyond it
CRUISE_AGL_M = 30.0
MIN_H_M, MIN_V_M = 50.0, 15.0  # config/default.toml separation minima


def _config(path: Path) -> Path:
    lat0, lon0, ground = PX4_DEFAULT_HOME
    path.write_text(
        f"""
[airspace]
origin_lat_deg = {lat0}
origin_lon_deg = {lon0}
ground_elevation_amsl_m = {ground}

[mavlink]
links = ["udpin:127.0.0.1:14550"]
"""
    )
    return path


def _rows(db: Path, sql: str) -> list[tuple[object, ...]]:
    if not db.exists():
        return []
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5.0)
    try:
        return list(con.execute(sql))
    except sqlite3.OperationalError:  # schema not created yet
        return []
    finally:
        con.close()


def _wait_rows(
    db: Path, sql: str, n: int, timeout_s: float, serve: subprocess.Popen[bytes]
) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        assert serve.poll() is None, "gcs-utm serve exited early"
        if len(_rows(db, sql)) >= n:
            return
        time.sleep(0.5)
    raise AssertionError(f"fewer than {n} rows of {sql!r} after {timeout_s} s")


def _closest(a: list[Sample], b: list[Sample], origin: tuple[float, float]) -> tuple[float, float]:
    """Over time-matched samples (within 0.1 s wall), the (horizontal, vertical) separation
    at the sample where the pair is closest against the cylinder minima."""
    worst = (math.inf, math.inf)
    worst_score = math.inf
    j = 0
    for s in a:
        while j + 1 < len(b) and abs(b[j + 1].t_s - s.t_s) <= abs(b[j].t_s - s.t_s):
            j += 1
        if not b or abs(b[j].t_s - s.t_s) > 0.1:
            continue
        ea, na = local_m(*origin, s.lat_deg, s.lon_deg)
        eb, nb = local_m(*origin, b[j].lat_deg, b[j].lon_deg)
        dh = math.hypot(ea - eb, na - nb)
        dv = abs(s.alt_amsl_m - b[j].alt_amsl_m)
        score = max(dh / MIN_H_M, dv / MIN_V_M)  # < 1: loss of separation
        if score < worst_score:
            worst_score, worst = score, (dh, dv)
    return worst


@pytest.mark.xfail(
    strict=True,
    reason="issue 18: PX4 refuses the uploaded resolution (DO_CHANGE_SPEED in frame 0); "
    "remove this mark with the fix",
)
@pytest.mark.timeout(420)
def test_crossing_px4_pair_is_resolved_and_flown(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, _ = PX4_DEFAULT_HOME
    starts = [offset_deg(lat0, lon0, -LEG_M, 0.0), offset_deg(lat0, lon0, 0.0, -LEG_M)]
    ends = [offset_deg(lat0, lon0, LEG_M, 0.0), offset_deg(lat0, lon0, 0.0, LEG_M)]
    for i, home in enumerate(starts):
        px4(instance=i, airframe="quad", home=home, speed=SPEED)
    pilots = [PilotLink(0), PilotLink(1)]
    serve = None
    db = tmp_path / "store.sqlite"
    log = (tmp_path / "serve.log").open("wb")
    try:
        for p in pilots:
            p.wait_ready()
        for p, start, end in zip(pilots, starts, ends, strict=True):
            assert p.home is not None
            alt = p.home[2] + CRUISE_AGL_M
            p.upload(mission_items(p.sys_id, start, [(*start, alt), (*end, alt)]))
        serve = subprocess.Popen(
            [sys.executable, "-m", "gcs_utm", "serve", "--headless", "--auto-accept",
             "--config", str(_config(tmp_path / "serve.toml")), "--db", str(db),
             "--speed", str(SPEED)],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
        )  # fmt: skip
        _wait_rows(db, "SELECT id FROM operations", 2, 40.0, serve)
        for p in pilots:
            p.arm_and_start()
        totals_before = [p.mission_current[-1][2] if p.mission_current else 0 for p in pilots]
        deadline = time.monotonic() + 150.0
        done = [False, False]
        while time.monotonic() < deadline and not all(done):
            for k, p in enumerate(pilots):
                p.poll(0.02)
                if p.samples and p.samples[-1].t_s > 0:
                    s = p.samples[-1]
                    e, n = local_m(*ends[k], s.lat_deg, s.lon_deg)
                    done[k] = done[k] or math.hypot(e, n) < 10.0
        assert serve.poll() is None, "gcs-utm serve exited during the flight"
    finally:
        if serve is not None and serve.poll() is None:
            serve.terminate()
            serve.wait(timeout=30)
        log.close()
        for p in pilots:
            p.close()
    text = (tmp_path / "serve.log").read_text(errors="replace")
    threats = _rows(db, "SELECT kind FROM threats WHERE kind = 'LOSS_OF_SEPARATION'")
    assert threats, f"no loss of separation predicted\n{text[-4000:]}"
    states = [str(r[0]) for r in _rows(db, "SELECT state FROM recommendations")]
    assert "applied" in states, f"no resolution applied (states {states})\n{text[-4000:]}"
    totals_after = [p.mission_current[-1][2] if p.mission_current else 0 for p in pilots]
    assert totals_after != totals_before, "neither PX4 flies a new mission"
    dh, dv = _closest(pilots[0].samples, pilots[1].samples, (lat0, lon0))
    report = json.dumps({"closest_h_m": round(dh, 2), "closest_v_m": round(dv, 2)})
    assert dh >= MIN_H_M or dv >= MIN_V_M, f"flown loss of separation: {report}\n{text[-4000:]}"
