"""Issue 31.4 on real PX4: a fixed wing's take-off raises no non-conformance threat.

A PX4 v1.15.2 SIH plane (airframe 10041, ``PX4_SIH_PLANE_PARAMS``) with a pilot's mission
(NAV_TAKEOFF to 30 m with the position a ground station gives it, 250 m ahead on the runway
heading, then a 500 m leg north at 30 m) sits beside ``gcs-utm serve --headless
--auto-accept``, which files its mission as an operation. It is armed and started: a runway
take-off towards the take-off position (lift-off about 18 m out, 30 m reached 95-99 m out),
then the leg at about 14 m/s. The take-off was filed as a straight line from home to the
take-off position, 18-28 m below the climbing plane: UAS_IN_CV. Now it is the climb-out at
the maximum climb rate (5 m/s, FW_T_CLMB_MAX) and the minimum airspeed, then level to the
take-off position: no UAS_OUT_OV / UAS_IN_CV and no recommendation through the take-off,
the climb-out and the leg."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mav

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, PX4_SIH_PLANE_PARAMS, SitlProcess
from tests.autopilot.closed_loop import Crossing, _config, _wait_operations, rows
from tests.autopilot.pilot import PilotLink, local_m, offset_deg

SPEED = 4.0  # as tests/autopilot/test_fly_plane.py
TAKEOFF_AGL_M = 30.0
TAKEOFF_AHEAD_M = 250.0
LEG_M = 500.0


def _mission(lat0: float, lon0: float, ground_m: float) -> list[object]:
    """NAV_TAKEOFF 250 m north at 30 m, then a waypoint 500 m north at 30 m (AMSL, as PX4's
    ground stations send a global frame)."""
    frame = mav.MAV_FRAME_GLOBAL_INT
    alt = ground_m + TAKEOFF_AGL_M

    def item(seq: int, cmd: int, north: float, p1: float = 0.0) -> object:
        lat, lon = offset_deg(lat0, lon0, 0.0, north)
        return mav.MAVLink_mission_item_int_message(
            1, 1, seq, frame, cmd, 0, 1, p1, 0.0, 0.0, float("nan"),
            round(lat * 1e7), round(lon * 1e7), alt, 0,
        )  # fmt: skip

    return [
        item(0, mav.MAV_CMD_NAV_TAKEOFF, TAKEOFF_AHEAD_M, 15.0),  # QGC's pitch; PX4 drops it
        item(1, mav.MAV_CMD_NAV_WAYPOINT, LEG_M),
    ]


@pytest.mark.timeout(300)
def test_px4_plane_takeoff_raises_no_conformance_threat(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, ground = PX4_DEFAULT_HOME
    crossing = Crossing(origin=(lat0, lon0), ground_amsl_m=ground)
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    cfg = _config(tmp_path / "serve.toml", crossing, ["udpin:127.0.0.1:14550"])
    px4(instance=0, airframe="plane", home=(lat0, lon0), speed=SPEED)
    pilot = PilotLink(0)
    serve: subprocess.Popen[bytes] | None = None
    try:
        pilot.wait_ready(90.0)
        pilot.set_params(PX4_SIH_PLANE_PARAMS)
        pilot.upload(_mission(lat0, lon0, ground))
        with log_path.open("wb") as log:
            serve = subprocess.Popen(
                [sys.executable, "-m", "gcs_utm", "-v", "serve", "--headless",
                 "--auto-accept", "--config", str(cfg), "--db", str(db),
                 "--speed", str(SPEED)],
                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            )  # fmt: skip
        _wait_operations(db, 1, 60.0, serve)
        pilot.arm_and_start(90.0)
        end = time.monotonic() + 2.0 * 120.0 / SPEED  # simulated: take-off and 500 m
        while not pilot.samples or _north_m(pilot) < LEG_M - 50.0:  # near the waypoint
            assert time.monotonic() < end, f"mission not flown: {pilot.statustexts[-6:]}"
            pilot.poll(0.5)
        assert serve.poll() is None, "gcs-utm serve exited"
    finally:
        pilot.close()
        if serve is not None and serve.poll() is None:
            serve.terminate()
            serve.wait(timeout=30)
    tail = log_path.read_text(errors="replace")[-4000:]
    threats = rows(db, "SELECT kind, detected_at_s, doc FROM threats")
    conformance = [t[:2] for t in threats if t[0] in ("UAS_OUT_OV", "UAS_IN_CV")]
    assert not conformance, f"non-conformance on a normal take-off: {conformance}\n{tail}"
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for a plane on its mission: {recs}\n{tail}"


def _north_m(pilot: PilotLink) -> float:
    last = pilot.samples[-1]
    return local_m(PX4_DEFAULT_HOME[0], PX4_DEFAULT_HOME[1], last.lat_deg, last.lon_deg)[1]
