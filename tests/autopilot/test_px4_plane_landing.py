"""Issue 31.4 on real PX4: a plan uploaded to a PX4 plane on its landing approach keeps its
landing, and the plane lands.

A PX4 v1.15.2 SIH plane (airframe 10041, ``PX4_SIH_PLANE_PARAMS``) flies a pilot's mission
like the nuisance soak's (a runway take-off 250 m north to 30 m, 700 m north at 40 m, the
approach waypoint 300 m west at 30 m, NAV_LAND 300 m south of home: PX4's fixed-wing landing
along the line from the approach waypoint, no DO_LAND_START). Once it flies its NAV_LAND, the
hub uploads what back_to_plan makes of its filed plan there: its position, the point of the
landing line it returns to, and the landing point (the filed plan's last waypoint, on the
ground). That upload replaced NAV_LAND by a waypoint on the ground, which the plane circled
0-4 m above the ground (the nuisance soak). Now the upload ends with the pilot's approach
and NAV_LAND, NAV_LAND current: the plane lands near the landing point (EXTENDED_SYS_STATE
ON_GROUND) and disarms.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mavlink.mission import MAV_CMD_NAV_LAND
from gcs_utm.clock import ScaledClock
from gcs_utm.model import FlightPlan, OperationId, SysId, Waypoint4D
from tests.autopilot.autopilots import PX4_DEFAULT_HOME, PX4_SIH_PLANE_PARAMS, SitlProcess
from tests.autopilot.closed_loop import Crossing, _config, _wait_operations, rows, serve_process
from tests.autopilot.pilot import PilotLink, local_m, offset_deg
from tests.mavlink.conftest import Sink

SPEED = 4.0  # as tests/autopilot/test_fly_plane.py
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
APPROACH = (-300.0, 300.0, 30.0)  # east, north, above ground
LAND = (0.0, -300.0, 0.0)
LAND_SEQ = 3
TOUCHDOWN_M = 150.0  # from the landing point: PX4 flares before it and rolls out after


def _mission() -> list[object]:
    """NAV_TAKEOFF 250 m north at 30 m, 700 m north at 40 m, the approach waypoint and
    NAV_LAND (AMSL, as PX4's ground stations send a global frame)."""
    legs = [
        (mav.MAV_CMD_NAV_TAKEOFF, (0.0, 250.0, 30.0), 15.0),
        (mav.MAV_CMD_NAV_WAYPOINT, (0.0, 700.0, 40.0), 0.0),
        (mav.MAV_CMD_NAV_WAYPOINT, APPROACH, 0.0),
        (mav.MAV_CMD_NAV_LAND, LAND, 0.0),
    ]
    out = []
    for seq, (cmd, (east, north, agl), p1) in enumerate(legs):
        lat, lon = offset_deg(LAT0, LON0, east, north)
        item = mav.MAVLink_mission_item_int_message(
            1, 1, seq, mav.MAV_FRAME_GLOBAL_INT, cmd, 0, 1, p1, 0.0, 0.0, float("nan"),
            round(lat * 1e7), round(lon * 1e7), GROUND_M + agl, 0,
        )  # fmt: skip
        out.append(item)
    return out


def _wp(east: float, north: float, alt_amsl_m: float, t_s: float) -> Waypoint4D:
    lat, lon = offset_deg(LAT0, LON0, east, north)
    return Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=alt_amsl_m, t_s=t_s)


def _back_to_plan(pilot: PilotLink, now_s: float) -> FlightPlan:
    """What back_to_plan makes of the filed plan on the landing leg: from the plane's
    position to the closest point of the leg (approach -> landing point, altitude along it),
    then the landing point on the ground (core/deconfliction/router.py)."""
    s = pilot.samples[-1]
    e, n = local_m(LAT0, LON0, s.lat_deg, s.lon_deg)
    (ae, an, aa), (le, ln, la) = APPROACH, LAND
    de, dn = le - ae, ln - an
    t = max(0.0, min(1.0, ((e - ae) * de + (n - an) * dn) / (de * de + dn * dn)))
    qe, qn, qa = ae + t * de, an + t * dn, GROUND_M + aa + t * (la - aa)
    to_q_s = math.hypot(qe - e, qn - n) / 15.0
    to_land_s = math.hypot(le - qe, ln - qn) / 15.0
    wps = (
        _wp(e, n, s.alt_amsl_m, now_s),
        _wp(qe, qn, qa, now_s + max(to_q_s, 1.0)),
        _wp(le, ln, GROUND_M + la, now_s + max(to_q_s, 1.0) + to_land_s),
    )
    return FlightPlan(operation_id=OperationId("plane"), version=2, waypoints=wps)


@pytest.mark.timeout(300)
async def test_px4_plane_on_its_approach_lands_after_a_utm_upload(
    px4: Callable[..., SitlProcess],
) -> None:
    px4(instance=0, airframe="plane", home=(LAT0, LON0), speed=SPEED)
    pilot = PilotLink(0)
    clock = ScaledClock(speed=SPEED)
    try:
        await asyncio.to_thread(pilot.wait_ready, 90.0)
        await asyncio.to_thread(pilot.set_params, PX4_SIH_PLANE_PARAMS)
        await asyncio.to_thread(pilot.upload, _mission())
        cfg = MavlinkConfig(links=("udpin:127.0.0.1:14550",))
        async with MavlinkHub(cfg, clock, Sink()) as hub:
            end = time.monotonic() + 30.0
            while not any(v.key.sys_id == 1 for v in hub.vehicles()):
                assert time.monotonic() < end, "PX4 not discovered"
                await asyncio.sleep(0.2)
            got = await hub.download_mission(SysId(1))
            assert [it.command for it in got][-1] == MAV_CMD_NAV_LAND
            await asyncio.to_thread(pilot.arm_and_start, 90.0)
            end = time.monotonic() + 240.0 / SPEED  # simulated: take-off to the approach
            while hub.state(SysId(1)).mission_seq != LAND_SEQ or not pilot.samples:
                assert time.monotonic() < end, f"never on its landing: {pilot.statustexts[-6:]}"
                await asyncio.to_thread(pilot.poll, 0.3)
            res = await hub.upload_plan(
                SysId(1), _back_to_plan(pilot, clock.now_s()), start_index=1, min_speed_mps=10.0
            )
            assert res.ok and res.verified, res
            end = time.monotonic() + 200.0 / SPEED  # simulated: the approach and touchdown
            st = hub.state(SysId(1))
            while st.landed is not True or st.armed:
                low = pilot.samples[-1].alt_amsl_m - GROUND_M if pilot.samples else math.nan
                assert time.monotonic() < end, (
                    f"not landed and disarmed: landed {st.landed}, armed {st.armed}, "
                    f"{low:.1f} m above the ground, item {st.mission_seq}: "
                    f"{pilot.statustexts[-6:]}"
                )
                await asyncio.to_thread(pilot.poll, 0.3)
            sent = await hub.download_mission(SysId(1))
        assert sent[-1].command == MAV_CMD_NAV_LAND, [it.command for it in sent]
        assert (sent[-1].x, sent[-1].y, sent[-1].z) == (got[-1].x, got[-1].y, got[-1].z)
        last = pilot.samples[-1]
        e, n = local_m(LAT0, LON0, last.lat_deg, last.lon_deg)
        off_m = math.hypot(e - LAND[0], n - LAND[1])
        print(f"landed {off_m:.0f} m from the landing point")
        assert off_m < TOUCHDOWN_M, f"landed {off_m:.0f} m from the landing point"
    finally:
        pilot.close()


@pytest.mark.timeout(300)
def test_px4_plane_landing_raises_no_conformance_threat(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    """The same mission flown to touchdown beside ``gcs-utm serve --headless
    --auto-accept``, which files it. The runway take-off towards the NAV_TAKEOFF position
    (lift-off about 18 m out, 30 m reached 95-99 m out) was filed as a straight line from
    home to that position, 18-28 m below the climbing plane (UAS_IN_CV); it is the climb-out
    at the maximum climb rate (FW_T_CLMB_MAX) and the minimum airspeed, then level. Then the
    approach, the glide along the landing line (PX4
    v1.15.2 SIH: from the approach waypoint straight to the landing point, within 3 m above
    that line) and the touchdown (about 45 m past the landing point): from take-off to
    touchdown no UAS_OUT_OV / UAS_IN_CV and no recommendation, and the plane lands on its
    own landing."""
    crossing = Crossing(origin=(LAT0, LON0), ground_amsl_m=GROUND_M)
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    cfg = _config(tmp_path / "serve.toml", crossing, ["udpin:127.0.0.1:14550"])
    px4(instance=0, airframe="plane", home=(LAT0, LON0), speed=SPEED)
    pilot = PilotLink(0)
    try:
        pilot.wait_ready(90.0)
        pilot.set_params(PX4_SIH_PLANE_PARAMS)
        pilot.upload(_mission())
        with serve_process(cfg, db, log_path, SPEED) as serve:
            _wait_operations(db, 1, 60.0, serve)
            pilot.arm_and_start(90.0)
            end = time.monotonic() + 420.0 / SPEED  # simulated: the mission to touchdown
            landed = False
            while not landed:
                assert time.monotonic() < end, f"not landed: {pilot.statustexts[-6:]}"
                for m in pilot.poll(0.5):
                    landed = landed or (m.get_type() == "HEARTBEAT" and not m.base_mode & 128)
    finally:
        pilot.close()
    tail = log_path.read_text(errors="replace")[-4000:]
    threats = rows(db, "SELECT kind, detected_at_s, doc FROM threats")
    conformance = [t[:2] for t in threats if t[0] in ("UAS_OUT_OV", "UAS_IN_CV")]
    assert not conformance, f"non-conformance on a normal landing: {conformance}\n{tail}"
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for a plane on its mission: {recs}\n{tail}"
    last = pilot.samples[-1]
    e, n = local_m(LAT0, LON0, last.lat_deg, last.lon_deg)
    assert math.hypot(e - LAND[0], n - LAND[1]) < TOUCHDOWN_M
