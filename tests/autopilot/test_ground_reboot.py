"""Issue 31 item 2 on real ArduCopter: a reboot on the ground starts a new pre-flight.

An ArduCopter with a mission sits disarmed beside ``gcs-utm serve --headless --auto-accept``
(on SERIAL1). It is restarted (the process killed and started again on the same working
directory, as a power cycle): while it acquires GPS again, gcs-utm used to raise
GNSS_DEGRADATION and then command a return_home mission and AUTO on the grounded copter.
Now its hazards on the ground are pre-flight findings: no threat from the vehicle, no
recommendation, and the reboot is seen (``sysid 1: rebooted``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.closed_loop import Crossing, _config, _wait_operations, rows, serve_process
from tests.autopilot.pilot import PilotLink, mission_items

SPEED = 5.0
AFTER_S = 10.0  # wall seconds after the reboot is seen: 50 simulated, GPS acquired before


@pytest.mark.timeout(240)
def test_a_rebooted_arducopter_on_the_ground_gets_no_emergency(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, ground, _ = ARDUPILOT_DEFAULT_HOME
    crossing = Crossing(origin=(lat0, lon0), ground_amsl_m=ground)
    workdir = tmp_path / "copter"
    copter = ardupilot(instance=0, vehicle="copter", speed=SPEED, workdir=workdir)
    wait_tcp_listening(5760)
    pilot = PilotLink(0, autopilot="ardupilot")
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    cfg = _config(tmp_path / "serve.toml", crossing, ["tcp:127.0.0.1:5762"])
    try:
        pilot.wait_ready()
        start = (lat0, lon0)
        pilot.upload(mission_items(1, start, [(lat0 + 0.001, lon0, 30.0)], autopilot="ardupilot"))
        with serve_process(cfg, db, log_path, SPEED) as serve:
            _wait_operations(db, 1, 40.0, serve)
            # power cycle: the same working directory (parameters, mission) and home
            pilot.close()
            copter.stop()
            ardupilot(instance=0, vehicle="copter", speed=SPEED, workdir=workdir)
            wait_tcp_listening(5760)
            pilot = PilotLink(0, autopilot="ardupilot")
            pilot.wait_ready()
            seen = time.monotonic() + 40.0  # serve's link comes back and hears the new boot
            while "sysid 1: rebooted" not in log_path.read_text(errors="replace"):
                assert time.monotonic() < seen, "the reboot was not seen"
                pilot.poll(0.5)
            end = time.monotonic() + AFTER_S
            while time.monotonic() < end:
                pilot.request_streams()
                pilot.poll(1.0)
            pilot.close()  # before serve stops: left open, unread, it made the stop ~10 s slower
    finally:
        pilot.close()
    text = log_path.read_text(errors="replace")
    tail = text[-4000:]
    vehicle = {"GNSS_DEGRADATION", "JAMMING_ATTACK", "LACK_OF_BATTERY", "COMMUNICATION_FAILURE"}
    kinds = [str(r[0]) for r in rows(db, "SELECT kind FROM threats")]
    assert not vehicle & set(kinds), f"emergency on the ground: {kinds}\n{tail}"
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for a copter on the ground: {recs}\n{tail}"
