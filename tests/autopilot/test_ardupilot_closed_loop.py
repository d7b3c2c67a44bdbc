"""Issue 26's acceptance: two real ArduCopters on crossing missions stay apart.

The pilots' own GCS (pilot.py) holds each copter's SERIAL0 (TCP 5760+10i, which also starts
SITL's clock), uploads the operator's mission, takes off in GUIDED and switches to AUTO;
``gcs-utm serve --headless --auto-accept`` connects to SERIAL1 (TCP 5762+10i), files the
operations, predicts the loss of separation, uploads a resolution ArduPilot accepts and
verifies, and the copter flies it from the intended item. The flown separation is measured
from ArduPilot's own positions on the pilot's link.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.closed_loop import Crossing, fly, upload_crossing
from tests.autopilot.pilot import PilotLink

SPEED = 4.0  # ArduPilot --speedup; serve --speed matches it


@pytest.mark.timeout(420)
def test_crossing_arducopter_pair_is_resolved_and_flown(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, ground, _ = ARDUPILOT_DEFAULT_HOME
    crossing = Crossing(origin=(lat0, lon0), ground_amsl_m=ground)
    for i, (lat, lon) in enumerate(crossing.starts()):
        ardupilot(instance=i, vehicle="copter", home=(lat, lon, ground, 0.0), speed=SPEED)
    pilots = []
    try:
        for i in range(2):
            wait_tcp_listening(5760 + 10 * i)
            pilots.append(PilotLink(i, autopilot="ardupilot"))
        for p in pilots:
            p.wait_ready()
        upload_crossing(pilots, crossing)
        links = ["tcp:127.0.0.1:5762", "tcp:127.0.0.1:5772"]
        out = fly(pilots, crossing, links, SPEED, tmp_path)
    finally:
        for p in pilots:
            p.close()
    tail = out.log[-4000:]
    assert "LOSS_OF_SEPARATION" in out.threat_kinds, f"no loss of separation predicted\n{tail}"
    assert "applied" in out.recommendation_states, f"{out.recommendation_states}\n{tail}"
    assert out.mission_totals_after != out.mission_totals_before, "no copter flies a new mission"
    assert not out.flown_loss, f"flown {out.closest_h_m:.1f} m / {out.closest_v_m:.1f} m\n{tail}"
    # no generated waypoint below the floor above the home at arming
    assert out.below_floor == [], out.below_floor
