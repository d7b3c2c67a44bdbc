"""``gcs-utm run SCENARIO --external --fly`` on two real PX4 quadrotors (issue 18 item 9).

Each PX4 starts on the ground at its operation's home (the first waypoint's position); the
run uploads each filed plan (verified by readback), arms, takes off and switches to mission
mode at the plan's first waypoint time. The report's tracks must pass every waypoint of each
plan, and the run must report each mission as uploaded, verified and started.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from gcs_utm.core.monitoring.loss import separation_ratio
from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.fly import FlyOp, closest_pass_m, run_fly, write_scenario
from tests.autopilot.pilot import local_m, offset_deg

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; run --speed matches it
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
# two quads well apart, so the UTM has no conflict to resolve and each vehicle flies the plan
# as filed
OPS = [
    FlyOp("UAS1", 1, "multirotor", "px4", (0.0, 0.0),
          [(0.0, 0.0, 25.0), (160.0, 0.0, 25.0), (160.0, 120.0, 25.0)], 8.0, 60.0),
    FlyOp("UAS2", 2, "multirotor", "px4", (0.0, -300.0),
          [(0.0, -300.0, 35.0), (-160.0, -300.0, 35.0)], 8.0, 60.0),
]  # fmt: skip
WAYPOINT_TOLERANCE_M = 12.0  # horizontal; PX4's acceptance radius and 0.5 s track samples
ALTITUDE_TOLERANCE_M = 5.0


@pytest.mark.timeout(240)
def test_two_px4_quads_fly_their_plans(px4: Callable[..., SitlProcess], tmp_path: Path) -> None:
    for op in OPS:
        lat, lon = offset_deg(LAT0, LON0, *op.home_m)
        px4(instance=op.sys_id - 1, airframe="quad", home=(lat, lon), speed=SPEED)
    scenario = write_scenario(
        tmp_path / "fly_px4.toml",
        "two PX4 quads fly their filed plans (--external --fly)",
        (LAT0, LON0, GROUND_M),
        130.0,
        OPS,
    )
    report, log = run_fly(scenario, tmp_path / "runs", SPEED, timeout_s=200.0)
    # the report's tracks (the UTM's view of PX4's positions): any of them passes each waypoint
    points = [
        (*local_m(LAT0, LON0, lat, lon), alt)
        for track in report["tracks"].values()
        for _t, lat, lon, alt in track
    ]
    for op in OPS:
        for e, n, a in op.waypoints:
            miss = closest_pass_m(points, e, n, GROUND_M + a, ALTITUDE_TOLERANCE_M)
            assert miss < WAYPOINT_TOLERANCE_M, (
                f"{op.uas}: no track passes waypoint ({e}, {n}, {a} AGL): {miss:.1f} m\n{log}"
            )
    # The report judges the pair once, on its effective minima (max(50, 10 + 10) m
    # horizontal, max(15, 10 + 10) m vertical), printed with the verdict and the distances at
    # the instant of the closest normalised approach, the one that decides it (issue 31).
    (pair,) = report["separation"]
    assert (pair["minimum_horizontal_m"], pair["minimum_vertical_m"]) == (50.0, 20.0), pair
    h_m, v_m = pair["horizontal_at_closest_m"], pair["vertical_at_closest_m"]
    ratio = float(separation_ratio(h_m, v_m, 50.0, 20.0, spherical=False))
    assert ratio == pytest.approx(pair["min_ratio"], abs=0.01), pair
    assert not pair["loss_of_separation"] and pair["min_ratio"] > 1.0, pair
    line = (
        f"separation UAS1-UAS2 (minima 50 m horizontal / 20 m vertical): closest at "
        f"{h_m} m horizontal, {v_m} m vertical: kept"
    )
    assert line in log, log
