"""`gcs-utm run` with its built-in vehicles: the report's telemetry delay (receipt minus the
vehicle's capture time mapped to UTC, in wall-clock ms) is the loopback latency at any
speed-up. It used to be the wall time between building the ground clock and the vehicles'
clock (about 100 ms here, mostly the first import of ``sitl``), because the two clocks had
separate monotonic anchors; the first run in a process shows it (the speed-1 case here), and
tests/mavlink/test_sitl.py checks the shared anchor deterministically."""

from __future__ import annotations

from pathlib import Path

import pytest

from gcs_utm.app import OperatorMode, RunOptions, run_scenario
from gcs_utm.settings import Settings

SCENARIO = Path(__file__).resolve().parents[2] / "config" / "scenarios" / "use_case_1.toml"

pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(120)]


@pytest.mark.parametrize(("speed", "duration_s"), [(1.0, 8.0), (10.0, 30.0)])
async def test_run_report_telemetry_delay_is_the_loopback_latency(
    tmp_path: Path, speed: float, duration_s: float
) -> None:
    options = RunOptions(
        speed=speed,
        headless=True,
        operator=OperatorMode.AUTO_ACCEPT,
        out_dir=tmp_path,
        duration_s=duration_s,
        figures=False,
        lead_s=1.0,
    )
    report = (await run_scenario(SCENARIO, Settings(), options)).to_json()
    tele = report["telemetry"]
    assert tele, report
    for name, t in tele.items():
        assert t["messages"] >= 10, (name, t)
        # loopback and one shared event loop: a few ms; whole-ms time_boot_ms: >= -1 ms
        assert t["min_delay_ms"] > -1.5 and t["mean_delay_ms"] < 25.0, (name, t)
