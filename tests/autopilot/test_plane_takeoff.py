"""Issue 31.4 on real ArduPlane: a normal mission raises no non-conformance threat.

An ArduPlane 4.6 SITL with the pilot's typical mission (take-off to 30 m at 15 deg, a
speed item of 14 m/s as a ground speed, a 1600 m leg north climbing to 60 m and an 800 m
leg west at 60 m, then DO_LAND_START, an approach descending to 30 m and NAV_LAND at home;
it arms with that mission only with RTL_AUTOLAND set; FLIGHT_OPTIONS makes it climb first)
sits beside ``gcs-utm serve --headless --auto-accept`` (on SERIAL1), which files its
mission as an operation. It is armed in AUTO and flies its runway take-off, its climb-out
along the heading to the first waypoint, its 24 m/s cruise (its plan is filed at 14 m/s:
48 s ahead at the first waypoint, beyond the 30 s time tolerance; Monitoring re-times it
along its track), its climb (21 m above the straight climb), three turns (90, 101 and
124 deg, up to 41 m outside the next leg) and its landing to touchdown.
The take-off was filed as a vertical climb at home and the plan timed at 5 m/s, so every
ArduPlane take-off opened UAS_OUT_OV and the auto-accepted plans wiped the landing
sequence; the climb and each turn opened UAS_IN_CV against the plan's polyline. Now: no
UAS_OUT_OV / UAS_IN_CV, no recommendation, and the mission on the plane still ends with its
landing sequence. And a plan the hub uploads to that ArduPlane keeps the landing sequence
at its end (read back equal) with airspeeds no lower than the minimum.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.mission import MissionItem
from gcs_utm.clock import ScaledClock
from gcs_utm.model import FlightPlan, OperationId, SysId, Waypoint4D
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.closed_loop import Crossing, _config, _wait_operations, rows, serve_process
from tests.autopilot.pilot import PilotLink, local_m, offset_deg
from tests.mavlink.conftest import Sink

SPEED = 5.0
LOITER_SPEED = 3.0
"""The loiter test's speed factor: Monitoring judges the track's position extrapolated to
serve's clock; on a circle, the further ahead the straighter (off the circle) it is."""
AUTO = 10  # ArduPlane's AUTO custom mode
FILED_MPS = 14.0  # the mission's speed item: a ground speed, which ArduPlane flies past
CRUISE_ALT_M = 60.0  # above home: a 30 m climb on the first leg from the take-off's 30 m
LAND_SEQ = 7  # NAV_LAND's seq in the mission with the speed item


def _mission(lat0: float, lon0: float, filed_mps: float | None = None) -> list[object]:
    """Home, NAV_TAKEOFF (15 deg, 30 m), [DO_CHANGE_SPEED ground speed ``filed_mps``,]
    1600 m north climbing to 60 m and then 800 m west at 60 m (two turns: 90 deg at the
    first waypoint, 150 deg at the second), DO_LAND_START, the approach descending to 30 m
    and NAV_LAND at home (altitudes above home, as ground stations send them)."""
    rel = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT

    def item(seq: int, cmd: int, east: float, north: float, alt: float, p1: float = 0.0) -> object:
        lat, lon = offset_deg(lat0, lon0, east, north)
        return mav.MAVLink_mission_item_int_message(
            1, 1, seq, rel, cmd, 0, 1, p1, 0.0, 0.0, 0.0, round(lat * 1e7), round(lon * 1e7),
            alt, 0,
        )  # fmt: skip

    takeoff = mav.MAVLink_mission_item_int_message(
        1, 1, 1, rel, mav.MAV_CMD_NAV_TAKEOFF, 0, 1, 15.0, 0, 0, 0, 0, 0, 30.0, 0
    )
    speed = []
    if filed_mps is not None:  # speed type 1: ArduPlane's minimum ground speed
        change = mav.MAV_CMD_DO_CHANGE_SPEED
        frame = mav.MAV_FRAME_MISSION
        speed = [
            mav.MAVLink_mission_item_int_message(
                1, 1, 2, frame, change, 0, 1, 1.0, filed_mps, -1.0, 0, 0, 0, 0.0, 0
            )
        ]
    k = len(speed)
    return [
        item(0, mav.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0),
        takeoff,
        *speed,
        item(2 + k, mav.MAV_CMD_NAV_WAYPOINT, 0.0, 1600.0, CRUISE_ALT_M),
        item(3 + k, mav.MAV_CMD_NAV_WAYPOINT, -800.0, 1600.0, CRUISE_ALT_M),
        item(4 + k, mav.MAV_CMD_DO_LAND_START, -800.0, 0.0, 0.0),
        item(5 + k, mav.MAV_CMD_NAV_WAYPOINT, -400.0, -400.0, 30.0),
        item(6 + k, mav.MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0),
    ]


@pytest.mark.timeout(300)
def test_arduplane_mission_raises_no_conformance_threat(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, _ground, _heading = ARDUPILOT_DEFAULT_HOME
    # simulated about 300 s (5.2 km at 22-24 m/s, take-off and landing); twice for load
    mission = _mission(lat0, lon0, FILED_MPS)
    commands = _fly_with_serve(ardupilot, tmp_path, mission, LAND_SEQ, 300.0)
    assert commands[-3:] == [189, 16, 21], f"landing sequence gone: {commands}"


def _loiter_mission(lat0: float, lon0: float) -> list[object]:
    """Home, NAV_TAKEOFF (15 deg, 30 m), 900 m north climbing to 60 m, a 20 s NAV_LOITER_TIME
    500 m west at 60 m without a radius (ArduPlane flies WP_LOITER_RAD, 80 m, clockwise, and
    reads param3 back as 1), DO_LAND_START, the approach to 30 m and NAV_LAND at home."""
    rel = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT

    def item(seq: int, cmd: int, east: float, north: float, alt: float, p1: float = 0.0) -> object:
        lat, lon = offset_deg(lat0, lon0, east, north)
        return mav.MAVLink_mission_item_int_message(
            1, 1, seq, rel, cmd, 0, 1, p1, 0.0, 0.0, 0.0, round(lat * 1e7), round(lon * 1e7),
            alt, 0,
        )  # fmt: skip

    takeoff = mav.MAVLink_mission_item_int_message(
        1, 1, 1, rel, mav.MAV_CMD_NAV_TAKEOFF, 0, 1, 15.0, 0, 0, 0, 0, 0, 30.0, 0
    )
    return [
        item(0, mav.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0),
        takeoff,
        item(2, mav.MAV_CMD_NAV_WAYPOINT, 0.0, 900.0, CRUISE_ALT_M),
        item(3, mav.MAV_CMD_NAV_LOITER_TIME, -500.0, 900.0, CRUISE_ALT_M, 20.0),
        item(4, mav.MAV_CMD_DO_LAND_START, -500.0, 0.0, 0.0),
        item(5, mav.MAV_CMD_NAV_WAYPOINT, -400.0, -400.0, 30.0),
        item(6, mav.MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0),
    ]


@pytest.mark.timeout(300)
def test_arduplane_loiter_and_landing_raise_no_conformance_threat(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    """The soak's loiter and landing (issue 31): ArduPlane joins its 80 m circle on its turn,
    circles 81-96 m from the centre for 20 s and on until it heads for the approach, then
    converges on the line from the centre and lands. It was filed on a 1 m circle (param3 read
    back as 1) and opened UAS_IN_CV / UAS_OUT_OV at the loiter; now nothing is raised. Its
    runway points 30 deg east of north, as the soak's plane stands after a landing: it climbs
    out along it and turns north to its first waypoint after the take-off (filed as a straight
    line from the climb's end, the soak's 45 deg turn ran 45-50 m outside the plan:
    UAS_IN_CV)."""
    lat0, lon0, _ground, _heading = ARDUPILOT_DEFAULT_HOME
    # simulated about 200 s (3.9 km at 22-24 m/s, a turn, take-off and landing)
    mission = _loiter_mission(lat0, lon0)
    commands = _fly_with_serve(
        ardupilot, tmp_path, mission, 6, 200.0, speed=LOITER_SPEED, heading_deg=30.0
    )
    assert commands[-3:] == [189, 16, 21], f"landing sequence gone: {commands}"


def _fly_with_serve(
    ardupilot: Callable[..., SitlProcess],
    tmp_path: Path,
    mission: list[object],
    land_seq: int,
    flight_s: float,
    speed: float = SPEED,
    heading_deg: float = 0.0,
) -> list[int]:
    """Fly ``mission`` on an ArduPlane beside ``serve --auto-accept`` to touchdown (within
    twice ``flight_s`` simulated), assert that no conformance threat and no recommendation
    was raised, and return the mission's commands as the plane has it at the end. The plane
    stands at home heading ``heading_deg`` (0: the runway points north)."""
    lat0, lon0, ground, _heading = ARDUPILOT_DEFAULT_HOME
    ardupilot(instance=0, vehicle="plane", speed=speed, home=(lat0, lon0, ground, heading_deg))
    wait_tcp_listening(5760)
    pilot = PilotLink(0, autopilot="ardupilot")
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    crossing = Crossing(origin=(lat0, lon0), ground_amsl_m=ground)
    cfg = _config(tmp_path / "serve.toml", crossing, ["tcp:127.0.0.1:5762"])
    try:
        pilot.wait_ready()
        # RTL_AUTOLAND: else "Arm: DO_LAND_START set and ..."; FLIGHT_OPTIONS bit 14
        # (IMMEDIATE_CLIMB_IN_AUTO): climb first to a higher waypoint, not on a glide slope
        pilot.set_params({"RTL_AUTOLAND": 2.0, "FLIGHT_OPTIONS": 16384.0})
        pilot.upload(mission)
        with serve_process(cfg, db, log_path, speed) as serve:
            _wait_operations(db, 1, 60.0, serve)
            pilot.set_mode(AUTO)
            pilot._arm(60.0)
            _fly_to_touchdown(pilot, ground, time.monotonic() + 2.0 * flight_s / speed, land_seq)
            commands = [int(it.command) for it in _download(pilot)]
            pilot.close()  # before serve stops: left open, unread, it made the stop ~10 s slower
    finally:
        pilot.close()
    tail = log_path.read_text(errors="replace")[-4000:]
    threats = rows(db, "SELECT kind, detected_at_s, doc FROM threats")
    conformance = [t for t in threats if t[0] in ("UAS_OUT_OV", "UAS_IN_CV")]
    assert not conformance, f"non-conformance on a normal mission: {conformance}\n{tail}"
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for a plane on its mission: {recs}\n{tail}"
    return commands


def _fly_to_touchdown(
    pilot: PilotLink, ground_amsl_m: float, end: float, land_seq: int = LAND_SEQ
) -> None:
    """Until the plane has flown to its NAV_LAND and stands on the ground (within 1.5 m of
    its home's altitude, its last four positions within 1 m of each other)."""
    while True:
        assert time.monotonic() < end, f"no touchdown: {pilot.statustexts[-8:]}"
        pilot.request_streams()
        pilot.poll(0.5)
        landing = any(seq >= land_seq for _, seq, _ in pilot.mission_current)
        last = pilot.samples[-4:]
        if not landing or len(last) < 4 or last[-1].alt_amsl_m > ground_amsl_m + 1.5:
            continue
        east, north = local_m(last[0].lat_deg, last[0].lon_deg, last[-1].lat_deg, last[-1].lon_deg)
        if abs(east) + abs(north) < 1.0:
            return


def _download(pilot: PilotLink) -> list[object]:
    """The plane's mission (MISSION_REQUEST_LIST, then each item)."""
    pilot.send(mav.MAVLink_mission_request_list_message(1, 1, 0))
    count = pilot.wait("MISSION_COUNT", 5.0).count
    items = []
    for seq in range(count):
        pilot.send(mav.MAVLink_mission_request_int_message(1, 1, seq, 0))
        items.append(pilot.wait("MISSION_ITEM_INT", 5.0, lambda m, s=seq: m.seq == s))
    return items


@pytest.mark.timeout(180)
async def test_arduplane_keeps_its_landing_sequence_after_a_utm_upload(
    ardupilot: Callable[..., SitlProcess],
) -> None:
    """The hub uploads a plan (airspeeds at least AIRSPEED_MIN) to an ArduPlane whose mission
    has a landing sequence: ArduPlane accepts it, its copy reads back equal by meaning
    (DO_LAND_START with its position and frame), and it ends with the pilot's sequence."""
    lat0, lon0, ground, _ = ARDUPILOT_DEFAULT_HOME
    ardupilot(instance=0, vehicle="plane", speed=SPEED)
    await asyncio.to_thread(wait_tcp_listening, 5760)
    cfg = MavlinkConfig(links=("tcp:127.0.0.1:5760",), ardupilot_stream_hz=10.0)
    async with MavlinkHub(cfg, ScaledClock(speed=SPEED), Sink()) as hub:
        end = time.monotonic() + 60.0
        while not any(v.key.sys_id == 1 for v in hub.vehicles()):
            assert time.monotonic() < end, "ArduPlane not discovered"
            await asyncio.sleep(0.2)
        pilot = [_item(m) for m in _mission(lat0, lon0)]
        for _ in range(30):  # NO_SPACE for a moment after boot: retried
            if (await hub.upload_items(SysId(1), pilot, set_mission_mode=False)).ok:
                break
            await asyncio.sleep(0.5)
        await hub.download_mission(SysId(1))
        plan = FlightPlan(
            operation_id=OperationId("plane"),
            version=2,
            waypoints=tuple(_north(lat0, lon0, ground + 60.0, k) for k in range(1, 4)),
        )
        res = await hub.upload_plan(SysId(1), plan, min_speed_mps=10.0, set_mission_mode=False)
        assert res.ok and res.verified, res
        got = await hub.download_mission(SysId(1))
    commands = [it.command for it in got]
    assert commands[-3:] == [189, 16, 21], commands
    speeds = [(it.param1, it.param2) for it in got if it.command == 178]
    assert speeds and all(s == (0.0, 10.0) for s in speeds), speeds  # 5 m/s asked: the minimum


def _north(lat0: float, lon0: float, alt_m: float, k: int) -> Waypoint4D:
    """Waypoint ``k`` of 300 m legs north at 5 m/s (below any plane's minimum airspeed)."""
    return Waypoint4D(
        lat_deg=lat0 + k * 300.0 / 110_540.0, lon_deg=lon0, alt_amsl_m=alt_m, t_s=k * 60.0
    )


def _item(m: Any) -> MissionItem:
    return MissionItem(
        seq=m.seq, command=m.command, frame=m.frame, autocontinue=m.autocontinue,
        param1=m.param1, param2=m.param2, param3=m.param3, param4=m.param4,
        x=m.x, y=m.y, z=m.z,
    )  # fmt: skip
