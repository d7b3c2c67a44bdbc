"""30 minutes of ``gcs-utm serve`` against a real PX4 (issue 18: no false COMMUNICATION_FAILURE).

The service (``gcs_utm.app.serve.serve``, in-process so the test can look inside: every part of
``serve --headless --auto-accept``) watches one PX4 SIH quadrotor on the ground, with a mission
(so it has an operation, which a lost link would turn into a COMMUNICATION_FAILURE threat and
a link-loss geofence), for 1800 s of PX4's simulated time, at a speed factor PX4 keeps up with
on 2 cores (``SOAK_SPEED``; PX4 SIH's clock then runs at 0.92-0.96 x the factor, 4-8 % slow
against the service's clock, more under load). Asserted: PX4's clock advanced 1800 s, no
COMMUNICATION_FAILURE threat, no link-loss geofence, no stale track, and capture times
bounded: never after their arrival, and at the end dated within 2 s of the vehicle's own clock
(a fixed offset would lag ~80 s).

The staleness limit is scaled with the speed factor: 30 simulated seconds are 3.75 s of wall
time at 8x (the default 5 s would be 0.6 s). On the shared 2-core machine the runs were
measured on (load average about 10 from other jobs), the worst capture delay over 30 minutes
was 3.0 and 21.2 simulated s (0.4 and 2.65 s of wall time) in two runs: with a 15 s limit the
second raised three false COMMUNICATION_FAILUREs from a scheduling stall, not from the link.
At 12x PX4 kept only 0.90 x the factor under that load. A real vehicle at speed 1 keeps the
default 5 s.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from gcs_utm.app.serve import serve
from gcs_utm.app.wiring import Runtime
from gcs_utm.model import SysId, ThreatKind
from gcs_utm.settings import settings_from_mapping
from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.pilot import PilotLink, mission_items, offset_deg

SOAK_SPEED = 8.0  # PX4_SIM_SPEED_FACTOR and serve --speed
SOAK_SIM_S = 1800.0
STALE_AFTER_S = 30.0


# Its margins were measured at a load average of about 10 on 2 cores (above): tests/check.sh
# runs it beside the rest of the suite, not in the PX4 lane.
@pytest.mark.load_tolerant
@pytest.mark.timeout(420)
async def test_serve_30_minutes_against_px4(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat, lon, ground = PX4_DEFAULT_HOME
    settings = settings_from_mapping(
        {
            "airspace": {
                "origin_lat_deg": lat,
                "origin_lon_deg": lon,
                "ground_elevation_amsl_m": ground,
            },
            "mavlink": {"links": ["udpin:127.0.0.1:14550"]},
            "tracking": {"stale_after_s": STALE_AFTER_S},
        },
        source="test_serve_soak",
    )
    p = px4(instance=0, airframe="quad", speed=SOAK_SPEED)
    pilot = PilotLink(0)
    pilot.wait_ready(60.0)
    _upload_mission(pilot, 0)  # the operator's mission, on PX4's onboard link
    box: list[Runtime] = []
    stop = asyncio.Event()

    async def keep(rt: Runtime) -> None:
        box.append(rt)

    task = asyncio.create_task(
        serve(
            settings,
            db_path=tmp_path / "soak.sqlite",
            operator="soak",
            headless=True,
            stop=stop,
            on_runtime=keep,
            speed=SOAK_SPEED,
        )
    )
    try:
        await _soak(box, p, pilot)
    finally:
        pilot.close()
        stop.set()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.wait_for(task, 30.0)


def _upload_mission(pilot: PilotLink, variant: int) -> None:
    """Take off and fly 200 m north, 30 m (+ ``variant`` m) above home."""
    lat, lon, _ground = PX4_DEFAULT_HOME
    assert pilot.home is not None
    north = offset_deg(lat, lon, 0.0, 200.0)
    pilot.upload(mission_items(1, (lat, lon), [(*north, pilot.home[2] + 30.0 + variant)]))


async def _until(cond: Callable[[], object], timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, what
        await asyncio.sleep(0.1)


async def _soak(box: list[Runtime], p: SitlProcess, pilot: PilotLink) -> None:
    await _until(lambda: box, 10.0, "serve did not start")
    rt = box[0]
    await _until(
        lambda: any(v.key.sys_id == 1 for v in rt.hub.vehicles()), 30.0, "PX4 not discovered"
    )
    st = rt.hub.state(SysId(1))
    await _until(lambda: st.last_position is not None, 60.0, "no position fix")
    # PX4 runs its mission-transfer timeouts on its own clock: at 12x the service has 1/12 of
    # them in wall time, and under load the download at discovery can time out on PX4's side
    # ("Operation timeout") and is not tried again until the mission changes. So the pilot
    # changes it (1 m higher) until the service has filed it.
    for variant in range(1, 7):
        with contextlib.suppress(AssertionError):
            await _until(lambda: rt.airspace.by_sys_id(SysId(1)), 5.0, "")
            break
        await asyncio.to_thread(_upload_mission, pilot, variant)
    await _until(lambda: rt.airspace.by_sys_id(SysId(1)), 5.0, "no operation from the mission")
    downloads = dict(rt.usm.vehicle_ops.counters)
    first_boot_ms, first_wall_s = st.last_boot_ms, time.monotonic()
    first_t_s = rt.clock.now_s()
    await _until(
        lambda: st.last_boot_ms - first_boot_ms >= SOAK_SIM_S * 1000,
        SOAK_SIM_S / SOAK_SPEED * 1.5 + 10,
        f"PX4 did not run {SOAK_SIM_S} s of sim time",
    )
    await asyncio.sleep(0.5)
    assert p.alive
    wall_s = time.monotonic() - first_wall_s
    sim_s = (st.last_boot_ms - first_boot_ms) / 1000.0
    rate = sim_s / (rt.clock.now_s() - first_t_s)
    stats = next(v for k, v in rt.usm.telemetry.items() if k.startswith("telemetry:1"))
    assert st.offset_s is not None
    lag_end_s = st.last_heard_t_s - (st.offset_s + st.last_boot_ms / 1000.0)
    comm = [t for t in rt.usm.threat_log if t.kind is ThreatKind.COMMUNICATION_FAILURE]
    fences = list(rt.geofence_history)
    print(
        f"serve soak: {sim_s:.0f} s of PX4 time in {wall_s:.0f} s wall (speed {SOAK_SPEED}: PX4 "
        f"at {sim_s / wall_s:.2f}x wall, {rate:.3f} x the service clock); {stats.count} "
        f"positions; capture delay {stats.delay_min_s:.4f}..{stats.delay_max_s:.3f} s; clock "
        f"jumps {st.clock_jumps}; lag at the end {lag_end_s:.3f} s; threats "
        f"{[t.kind.value for t in rt.usm.threat_log]}; geofences {fences}; filing {downloads}"
    )
    assert rt.airspace.by_sys_id(SysId(1)) is not None
    assert comm == [], comm
    assert fences == [], fences  # a link-loss geofence follows a COMMUNICATION_FAILURE
    assert rt.tracker.counters["stale_raised"] == 0
    assert stats.delay_min_s >= -1e-6  # never dated after its arrival
    assert lag_end_s < 2.0
