"""Issue 31.4 on real ArduPlane: a plan uploaded while the plane loiters keeps its loiter and
its landing sequence, and the plane lands on the pilot's landing.

An ArduPlane 4.6 SITL flies the soak's mission (take-off, 900 m north at 60 m, a 20 s
NAV_LOITER_TIME 500 m west without a radius: ArduPlane's WP_LOITER_RAD, 80 m, clockwise;
DO_LAND_START, the approach, NAV_LAND at home). Half way round its circle the hub uploads
what a back_to_plan is (the plane's position, then the filed plan on from the circle's point
ahead of it, as serve files the mission: :mod:`gcs_utm.services.fixed_wing_plan`). The
upload holds the plane's position, the circle's point after it, the pilot's loiter item (its
time cut to what the plan has left of it), none of the circle's other points as waypoints
(ArduPlane accepts each WP_RADIUS early), airspeeds (not ground speeds) no lower than its
AIRSPEED_MIN, and the landing sequence at its end; the plane goes on round its own ring (as
the circle's waypoints it cut inside to 39 m, then flew 112-115 m from the centre), leaves it
and lands on that landing at home (about 45 s at speed 5).
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections.abc import Callable

import pytest

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.loiter_kept import MAV_CMD_NAV_LOITER_TIME
from adapters.mavlink.mission import MAV_CMD_NAV_LAND, MAV_CMD_NAV_WAYPOINT, MissionItem
from gcs_utm.clock import ScaledClock
from gcs_utm.model import FlightPlan, OperationId, Position, SysId, Waypoint4D
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services.mission_points import mission_points, plan_from_points
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.pilot import PilotLink, local_m
from tests.autopilot.test_plane_takeoff import AUTO, _loiter_mission
from tests.mavlink.conftest import Sink

SPEED = 5.0
RADIUS_M = 80.0  # WP_LOITER_RAD in ArduPlane's SITL defaults
RING_M = (60.0, 108.0)
"""ArduPlane's own ring round the centre of its 80 m loiter, restarted by the upload: 73-100 m
measured; sent as the circle's waypoints (before) it cut inside to 39 m, then flew 112-115 m."""
ON_RING_M = 100.0  # on its way round the circle, before the upload
LOITER_SEQ = 3
CRUISE_MPS = 22.0  # AIRSPEED_CRUISE in its SITL defaults


def _filed(mission: list[MissionItem], home: Position) -> FlightPlan:
    """The plan serve files for ``mission`` (vehicle_ops: its points as ArduPlane flies them),
    timed from 0."""
    points = mission_points(mission, home=home, cruise_speed_mps=CRUISE_MPS, skip_first=True)
    assert points is not None
    flown = fw.fixed_wing_points(
        points, ground_alt_m=home.alt_amsl_m, climb_rate_mps=5.0, descent_rate_mps=3.0,
        loiter_radius_m=RADIUS_M, home_deg=(home.lat_deg, home.lon_deg), takeoff_heading_deg=0.0,
        heads_for_takeoff_position=False, turn_after_takeoff=True,
    )  # fmt: skip
    plan = plan_from_points(flown, OperationId("sys1"), t_s=0.0)
    assert plan is not None
    return plan


def _from_circle(plan: FlightPlan, centre: MissionItem, at: Waypoint4D) -> FlightPlan:
    """A back_to_plan of the plane at ``at`` on the circle: its position, then the plan on
    from the circle's point after the one nearest it, shifted to continue from there."""
    wps = plan.waypoints
    on = [k for k, w in enumerate(wps) if abs(_from_centre_m(centre, w) - RADIUS_M) < 1.0]
    near = min(on, key=lambda k: _distance_m(wps[k], at))
    nxt = wps[min(near + 1, on[-1])]
    shift = at.t_s + _distance_m(nxt, at) / CRUISE_MPS - nxt.t_s
    rest = [
        Waypoint4D(lat_deg=w.lat_deg, lon_deg=w.lon_deg, alt_amsl_m=w.alt_amsl_m, t_s=w.t_s + shift)
        for w in wps[min(near + 1, on[-1]) :]
    ]
    return FlightPlan(operation_id=plan.operation_id, version=2, waypoints=(at, *rest))


def _distance_m(a: Waypoint4D, b: Waypoint4D) -> float:
    return math.hypot(*local_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg))


def _from_centre_m(centre: MissionItem, w: Waypoint4D | Position) -> float:
    return math.hypot(*local_m(centre.lat_deg, centre.lon_deg, w.lat_deg, w.lon_deg))


def _poll(pilot: PilotLink, stop: threading.Event) -> None:
    while not stop.is_set():
        pilot.request_streams()
        pilot.poll(0.3)


async def _until(what: str, cond: Callable[[], bool], timeout_s: float, pilot: PilotLink) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, f"{what}: not within {timeout_s} s {pilot.statustexts[-6:]}"
        await asyncio.sleep(0.1)


@pytest.mark.timeout(300)
async def test_arduplane_upload_on_its_loiter_keeps_the_loiter_and_lands(
    ardupilot: Callable[..., SitlProcess],
) -> None:
    lat0, lon0, ground, _ = ARDUPILOT_DEFAULT_HOME
    home = Position(lat_deg=lat0, lon_deg=lon0, alt_amsl_m=ground)
    ardupilot(instance=0, vehicle="plane", speed=SPEED, home=(lat0, lon0, ground, 0.0))
    await asyncio.to_thread(wait_tcp_listening, 5760)
    pilot = PilotLink(0, autopilot="ardupilot")
    stop = threading.Event()
    poller = threading.Thread(target=_poll, args=(pilot, stop), daemon=True)
    cfg = MavlinkConfig(links=("tcp:127.0.0.1:5762",), ardupilot_stream_hz=10.0)
    try:
        await asyncio.to_thread(pilot.wait_ready)
        # RTL_AUTOLAND: else "Arm: DO_LAND_START set and ..."; FLIGHT_OPTIONS: climb first
        await asyncio.to_thread(pilot.set_params, {"RTL_AUTOLAND": 2.0, "FLIGHT_OPTIONS": 16384.0})
        await asyncio.to_thread(pilot.upload, _loiter_mission(lat0, lon0))
        async with MavlinkHub(cfg, ScaledClock(speed=SPEED), Sink()) as hub:
            await _until("discovered", lambda: any(v.key.sys_id == 1 for v in hub.vehicles()),
                         60.0, pilot)  # fmt: skip
            mission = await hub.download_mission(SysId(1))
            loiter = mission[LOITER_SEQ]
            assert loiter.command == MAV_CMD_NAV_LOITER_TIME, mission
            await asyncio.to_thread(pilot.set_mode, AUTO)
            await asyncio.to_thread(pilot._arm, 60.0)
            poller.start()

            def on_circle_s() -> float:  # seconds (simulated) on the loiter item, on its ring
                t = [t for t, seq, _ in pilot.mission_current if seq == LOITER_SEQ]
                ring = pilot.samples and _from_centre_m(loiter, pilot.samples[-1]) < ON_RING_M
                return (time.monotonic() - t[0]) * SPEED if t and ring else 0.0

            # half way round the 20 s (about 0.9 of a turn) after joining the circle
            await _until("on the loiter's circle", lambda: on_circle_s() > 14.0, 120.0, pilot)
            s = pilot.samples[-1]
            at = Waypoint4D(lat_deg=s.lat_deg, lon_deg=s.lon_deg, alt_amsl_m=s.alt_amsl_m, t_s=0.0)
            plan = _from_circle(_filed(mission, home), loiter, at)
            res = await hub.upload_plan(
                SysId(1), plan, home=home, min_speed_mps=10.0, set_mission_mode=False
            )
            assert res.ok and res.verified, res
            got = await hub.download_mission(SysId(1))
            t_upload = time.monotonic()
        commands = [it.command for it in got]
        assert commands.count(MAV_CMD_NAV_LOITER_TIME) == 1, commands
        kept = commands.index(MAV_CMD_NAV_LOITER_TIME)
        # it starts at its own position, then the circle's point after it (both accepted at
        # once: WP_RADIUS), then the loiter
        first, entry = got[res.current_seq or 0], got[kept - 2]
        assert _from_centre_m(first, at) < 10.0 and kept - (res.current_seq or 0) == 4, commands
        assert abs(_from_centre_m(loiter, entry) - RADIUS_M) < 1.0, entry
        assert (got[kept].x, got[kept].y, got[kept].z) == (loiter.x, loiter.y, loiter.z)
        assert got[kept].param1 <= 20.0, got[kept]
        circle = [
            it.seq
            for it in got[1:]
            if it.command == MAV_CMD_NAV_WAYPOINT
            and abs(_from_centre_m(loiter, it) - RADIUS_M) < 5
            and it.seq != kept - 2
        ]
        assert circle == [], f"the circle's points sent as waypoints: {circle}"  # but its entry
        assert commands[-3:] == [189, 16, MAV_CMD_NAV_LAND], commands
        speeds = [(it.param1, it.param2) for it in got if it.command == 178]
        assert speeds and all(kind == 0.0 and mps >= 10.0 for kind, mps in speeds), speeds
        land_seq = len(got) - 1
        # it goes on round its ring, leaves it and lands on the pilot's landing at home
        await _until(
            "touchdown on its landing",
            lambda: _landed(pilot, land_seq, ground),
            2.0 * 150.0 / SPEED,
            pilot,
        )
    finally:
        stop.set()
        if poller.is_alive():
            poller.join(timeout=5.0)
        pilot.close()
    after = [s for s in pilot.samples if s.t_s >= t_upload]
    on_loiter = [t for t, seq, _ in pilot.mission_current if t >= t_upload and seq == kept]
    ring = [_from_centre_m(loiter, s) for s in after if on_loiter and s.t_s <= on_loiter[-1]]
    assert ring and RING_M[0] < min(ring) and max(ring) < RING_M[1], (
        f"off its loiter's ring: {min(ring, default=0.0):.0f}-{max(ring, default=0.0):.0f} m"
    )
    last = pilot.samples[-1]
    east, north = local_m(lat0, lon0, last.lat_deg, last.lon_deg)
    assert math.hypot(east, north) < 150.0, f"landed {math.hypot(east, north):.0f} m from home"


def _landed(pilot: PilotLink, land_seq: int, ground_amsl_m: float) -> bool:
    """On its NAV_LAND and standing on the ground (within 1.5 m of home's altitude, its last
    four positions within 1 m of each other)."""
    landing = any(seq >= land_seq for _, seq, _ in pilot.mission_current[-20:])
    last = pilot.samples[-4:]
    if not landing or len(last) < 4 or last[-1].alt_amsl_m > ground_amsl_m + 1.5:
        return False
    east, north = local_m(last[0].lat_deg, last[0].lon_deg, last[-1].lat_deg, last[-1].lon_deg)
    return abs(east) + abs(north) < 1.0
