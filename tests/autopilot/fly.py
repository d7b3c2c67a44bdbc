"""What the real-autopilot ``gcs-utm run --external --fly`` tests share: the scenario they
file, the run itself and the report checks every one of them makes.

A test describes its vehicles as :class:`FlyOp` (home and waypoints in metres from the
scenario's origin), writes them with :func:`write_scenario`, and :func:`run_fly` runs the
ground service against the autopilots already started by the test, returning the report once
every mission has been uploaded, verified by readback, armed and started.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

Waypoint = tuple[float, float, float]  # east m, north m, altitude above ground m


@dataclass(frozen=True)
class FlyOp:
    """One operation as the tests file it: a vehicle starting on the ground at ``home_m``."""

    uas: str
    sys_id: int
    vehicle: str  # "multirotor" or "fixed_wing"
    autopilot: str  # "px4" or "ardupilot"
    home_m: tuple[float, float]
    waypoints: Sequence[Waypoint]
    cruise_speed_mps: float
    start_s: float
    operational_volume_m: float | None = None  # default: 100 m fixed wing, 10 m multirotor
    conops: str = "survey"

    @property
    def fixed_wing(self) -> bool:
        return self.vehicle == "fixed_wing"

    def toml(self) -> str:
        points = ", ".join(
            f"{{ east_m = {e}, north_m = {n}, alt_agl_m = {a} }}" for e, n, a in self.waypoints
        )
        volume_m = self.operational_volume_m or (100.0 if self.fixed_wing else 10.0)
        icao_prefix = "c0ffe" if self.autopilot == "px4" else "c0ffa"
        return f"""
[[operations]]
id = "{self.uas}"
sys_id = {self.sys_id}
priority = {self.sys_id}
vehicle = "{self.vehicle}"
autopilot = "{self.autopilot}"
icao24 = "{icao_prefix}{self.sys_id}"
conops = "{self.conops}"
operator = "pilot-{self.uas.lower()}"
cruise_speed_mps = {self.cruise_speed_mps}
flight_geometry_m = {20.0 if self.fixed_wing else 5.0}
operational_volume_m = {volume_m}
endurance_s = 1200.0
max_climb_rate_mps = {4.0 if self.fixed_wing else 2.0}
start_s = {self.start_s}
home = {{ east_m = {self.home_m[0]}, north_m = {self.home_m[1]}, alt_agl_m = 0.0 }}
waypoints = [{points}]
"""


def write_scenario(
    path: Path,
    description: str,
    origin: tuple[float, float, float],
    duration_s: float,
    ops: Iterable[FlyOp],
) -> Path:
    """A scenario named after ``path``'s stem; ``origin`` is (lat deg, lon deg, ground AMSL m)."""
    lat0, lon0, ground_m = origin
    header = f"""
[scenario]
name = "{path.stem}"
description = "{description}"
duration_s = {duration_s}

[airspace]
origin_lat_deg = {lat0}
origin_lon_deg = {lon0}
ground_elevation_amsl_m = {ground_m}
"""
    path.write_text(header + "".join(op.toml() for op in ops))
    return path


def run_fly(
    scenario: Path,
    out_dir: Path,
    speed: float,
    *,
    timeout_s: float = 240.0,
    extra_args: Sequence[str] = (),
    while_running: Callable[[], None] | None = None,
) -> tuple[dict[str, Any], str]:
    """Run ``gcs-utm run SCENARIO --external --fly --auto-accept`` at ``speed`` and return
    (report, the tail of its output). ``while_running`` is called repeatedly during the run
    (a test reading the autopilots' own positions). Fails unless the run exits cleanly and
    every mission was uploaded, verified, armed and started."""
    args = [sys.executable, "-m", "gcs_utm", "run", str(scenario), "--external", "--fly",
            "--auto-accept", "--headless", "--no-figures", "--speed", str(speed),
            "--out", str(out_dir), *extra_args]  # fmt: skip
    t0 = time.monotonic()
    with subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True
    ) as run:
        if while_running is None:
            output, _ = _communicate(run, timeout_s)
        else:
            while run.poll() is None and time.monotonic() - t0 < timeout_s:
                while_running()
            if run.poll() is None:
                run.kill()
            output = run.stdout.read() if run.stdout else ""
    log = output[-6000:]
    print(f"run: {time.monotonic() - t0:.0f} s wall")
    assert run.returncode == 0, log
    report: dict[str, Any] = json.loads((out_dir / f"{scenario.stem}.json").read_text())
    threats = [(t["kind"], t["uas"], t["detected_at_s"]) for t in report["threats"]]
    print(f"threats: {threats}")
    for f in report["fly"]:
        assert not f["error"], f"{f['uas']}: {f}\n{log}"
        assert f["uploaded"] and f["verified"] and f["armed"] and f["started"], f"{f}\n{log}"
        print(f"{f['uas']}: mission started {f['late_s']} s after its first waypoint's time")
    return report, log


def _communicate(run: subprocess.Popen[str], timeout_s: float) -> tuple[str, str]:
    try:
        return run.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        run.kill()
        out, err = run.communicate()
        return f"{out}\n(killed after {timeout_s:.0f} s)", err


def closest_pass_m(
    points: Iterable[tuple[float, float, float]],
    east_m: float,
    north_m: float,
    alt_amsl_m: float,
    alt_tol_m: float,
) -> float:
    """Horizontal distance of the closest of ``points`` (east m, north m, altitude AMSL m)
    within ``alt_tol_m`` of ``alt_amsl_m``; inf when none is."""
    return min(
        (
            math.hypot(e - east_m, n - north_m)
            for e, n, a in points
            if abs(a - alt_amsl_m) < alt_tol_m
        ),
        default=math.inf,
    )
