"""Issue 18's acceptance: two real PX4 quadrotors on crossing missions stay apart.

The pilots' own GCS (pilot.py, on PX4's API link) uploads each operator's mission and starts
it; ``gcs-utm serve --headless --auto-accept`` holds the GCS link (14550), files the vehicles'
operations, predicts the loss of separation, uploads a resolution PX4 accepts and verifies, and
PX4 flies it. The flown separation is measured from PX4's own positions, not gcs-utm's tracks.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import Crossing, fly, upload_crossing
from tests.autopilot.pilot import PilotLink

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; serve --speed matches it


@pytest.mark.timeout(420)
def test_crossing_px4_pair_is_resolved_and_flown(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    crossing = Crossing(origin=PX4_DEFAULT_HOME[:2], ground_amsl_m=PX4_DEFAULT_HOME[2])
    for i, home in enumerate(crossing.starts()):
        px4(instance=i, airframe="quad", home=home, speed=SPEED)
    pilots = [PilotLink(0), PilotLink(1)]
    try:
        for p in pilots:
            p.wait_ready()
        upload_crossing(pilots, crossing)
        out = fly(pilots, crossing, ["udpin:127.0.0.1:14550"], SPEED, tmp_path)
    finally:
        for p in pilots:
            p.close()
    tail = out.log[-4000:]
    assert "LOSS_OF_SEPARATION" in out.threat_kinds, f"no loss of separation predicted\n{tail}"
    assert "applied" in out.recommendation_states, f"{out.recommendation_states}\n{tail}"
    assert out.mission_totals_after != out.mission_totals_before, "no PX4 flies a new mission"
    assert not out.flown_loss, f"flown {out.closest_h_m:.1f} m / {out.closest_v_m:.1f} m\n{tail}"
    # no generated waypoint below the floor above the home at arming
    assert out.below_floor == [], out.below_floor
