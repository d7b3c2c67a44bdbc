"""Issue 31.4 on real PX4: a PX4 plane that takes off from its runway, meets an intruder and
flies the plan ``serve --auto-accept`` uploads ends on the pilot's own landing pattern.

The PX4 twin of ``test_plane_lands_after_plan.py``: a PX4 v1.15.2 SIH plane (airframe 10041,
``PX4_SIH_PLANE_PARAMS``, speed 4) holds the pilot's mission: a runway take-off towards
250 m north at 30 m, 1700 m north at 40 m, then PX4's landing pattern (DO_LAND_START in the
mission frame, the only one PX4 takes it in; the approach waypoint 600 m north of the landing
point at 30 m, a 153 deg turn from the leg; NAV_LAND 500 m from home: 400 m west, 300 m
north). Once it is airborne a hovering helicopter appears on an SBS-1 feed 1200 m north of
home at the plane's cruise altitude. Serve predicts the INTRUDER threat, decides (go_up) and
uploads; the plane flies the plan and lands. Checked on the pilot's link (PX4's API link): a
plan applied and on the plane, the mission read back after touchdown ending with the pilot's
DO_LAND_START, approach and NAV_LAND item for item, and the plane down and disarmed near the
pilot's landing point, not at home. Before, every avoidance was dropped (the 153 deg turn,
raised by go_up, judged as a generated turn: core/deconfliction/safety.py), serve held the
plane again and again and it did not land in time.

The intruder minima are measured, not asserted: PX4 came 133-148 m / 44-49 m from the
helicopter (inside 150 m / 50 m) after the go_up, a back_to_plan of a UAS_OUT_OV that opened
right after the upload, and a go_up of 0 m (docs/autopilots.md, "Landing sequences").
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mav

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, PX4_SIH_PLANE_PARAMS, SitlProcess
from tests.autopilot.closed_loop import Crossing, _config, rows, serve_process
from tests.autopilot.pilot import PilotLink, local_m, offset_deg
from tests.autopilot.test_plane_lands_after_plan import (
    INTRUDER_H_M,
    INTRUDER_V_M,
    _same_item,
    _sbs_feed,
    _wait_filed,
    adsb_config,
    hovering_intruder,
)

SPEED = 4.0  # PX4_SIM_SPEED_FACTOR; serve --speed matches it
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
CRUISE_AGL_M = 40.0
LAND_EN_M = (-400.0, 300.0)  # the pilot's NAV_LAND, east/north of home
INTRUDER_EN_M = (0.0, 1200.0)  # the helicopter, on the leg north at the cruise altitude
TOUCHDOWN_M = 150.0  # from the landing point: PX4 flares before it and rolls out after
FLIGHT_S = 380.0  # simulated: about 3.3 km at 14-15 m/s, the take-off, avoidance and landing


def _mission() -> list[Any]:
    """NAV_TAKEOFF 250 m north at 30 m, 1700 m north at 40 m, DO_LAND_START, the approach
    waypoint 600 m north of the landing point at 30 m, NAV_LAND (AMSL, as PX4's ground
    stations send a global frame)."""
    east, north = LAND_EN_M
    legs = [
        (mav.MAV_CMD_NAV_TAKEOFF, (0.0, 250.0, 30.0), 15.0),
        (mav.MAV_CMD_NAV_WAYPOINT, (0.0, 1700.0, CRUISE_AGL_M), 0.0),
        (mav.MAV_CMD_DO_LAND_START, (east, north, 0.0), 0.0),
        (mav.MAV_CMD_NAV_WAYPOINT, (east, north + 600.0, 30.0), 0.0),
        (mav.MAV_CMD_NAV_LAND, (east, north, 0.0), 0.0),
    ]
    out = []
    for seq, (cmd, (e, n, agl), p1) in enumerate(legs):
        lat, lon = offset_deg(LAT0, LON0, e, n)
        frame, x, y, z = (
            mav.MAV_FRAME_GLOBAL_INT,
            round(lat * 1e7),
            round(lon * 1e7),
            GROUND_M + agl,
        )
        if cmd == mav.MAV_CMD_DO_LAND_START:  # PX4 takes it only in the mission frame
            frame, x, y, z = mav.MAV_FRAME_MISSION, 0, 0, 0.0
        item = mav.MAVLink_mission_item_int_message(
            1, 1, seq, frame, cmd, 0, 1, p1, 0.0, 0.0, 0.0, x, y, z, 0
        )
        out.append(item)
    return out


def _download(pilot: PilotLink) -> list[Any]:
    """The plane's mission (MISSION_REQUEST_LIST, then each item; resent: UDP)."""
    count = None
    while count is None:
        pilot.send(mav.MAVLink_mission_request_list_message(1, 1, 0))
        try:
            count = pilot.wait("MISSION_COUNT", 1.0).count
        except TimeoutError:
            continue
    items = []
    for seq in range(count):
        for attempt in range(10):
            pilot.send(mav.MAVLink_mission_request_int_message(1, 1, seq, 0))
            try:
                items.append(pilot.wait("MISSION_ITEM_INT", 1.0, lambda m, s=seq: m.seq == s))
                break
            except TimeoutError:
                if attempt == 9:
                    raise
    pilot.send(mav.MAVLink_mission_ack_message(1, 1, 0, 0))
    return items


@pytest.mark.timeout(300)
def test_px4_plane_avoids_an_intruder_and_lands_on_its_own_landing(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    px4(instance=0, airframe="plane", home=(LAT0, LON0), speed=SPEED)
    pilot = PilotLink(0)
    mission = _mission()
    ilat, ilon = offset_deg(LAT0, LON0, *INTRUDER_EN_M)
    intruder_amsl_m = GROUND_M + CRUISE_AGL_M
    airborne = threading.Event()

    intruder = hovering_intruder(ilat, ilon, intruder_amsl_m, airborne)

    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    crossing = Crossing(origin=(LAT0, LON0), ground_amsl_m=GROUND_M)
    try:
        pilot.wait_ready(90.0)
        pilot.set_params(PX4_SIH_PLANE_PARAMS)
        pilot.upload(mission)
        uploaded = _download(pilot)  # the pilot's mission as the plane holds it
        assert [int(it.command) for it in uploaded] == [int(it.command) for it in mission]
        with _sbs_feed(intruder) as port:
            cfg = _config(tmp_path / "serve.toml", crossing, ["udpin:127.0.0.1:14550"])
            cfg.write_text(cfg.read_text() + adsb_config(port))
            with serve_process(cfg, db, log_path, SPEED) as serve:
                _wait_filed(pilot, db, serve)
                pilot.arm_and_start(90.0)
                _fly(pilot, airborne)
                got = _download(pilot)
    finally:
        pilot.close()
    tail = log_path.read_text(errors="replace")[-4000:]
    threats = [str(r[0]) for r in rows(db, "SELECT kind FROM threats")]
    assert "INTRUDER" in threats, f"no intruder threat: {threats}\n{tail}"
    recs = [str(r[0]) for r in rows(db, "SELECT state FROM recommendations")]
    assert "applied" in recs, f"no plan applied: {recs}\n{tail}"
    assert len(got) != len(uploaded) or not all(map(_same_item, got, uploaded)), "not replaced"
    commands = [int(it.command) for it in got]
    assert len(got) >= 3 and all(map(_same_item, got[-3:], uploaded[-3:])), commands
    last = pilot.samples[-1]
    from_landing_m = math.hypot(
        *local_m(*offset_deg(LAT0, LON0, *LAND_EN_M), last.lat_deg, last.lon_deg)
    )
    from_home_m = math.hypot(*local_m(LAT0, LON0, last.lat_deg, last.lon_deg))
    assert from_landing_m < TOUCHDOWN_M, f"landed {from_landing_m:.0f} m from its landing"
    assert from_home_m > 300.0, f"landed {from_home_m:.0f} m from home"
    # not asserted: the intruder minima (docs/autopilots.md, "Landing sequences": PX4 came
    # 133-148 m / 44-49 m from the helicopter after the go_up, inside the 150 m / 50 m)
    h, v = _closest(pilot, intruder_amsl_m)
    print(
        f"landed {from_landing_m:.0f} m from its landing, {from_home_m:.0f} m from home; "
        f"closest {h:.0f} m / {v:.0f} m to the intruder"
    )


def _fly(pilot: PilotLink, airborne: threading.Event) -> None:
    """Follow the plane until it is disarmed after its flight (within twice
    :data:`FLIGHT_S` simulated), setting ``airborne`` 20 m above the ground."""
    end = time.monotonic() + 2.0 * FLIGHT_S / SPEED
    while True:
        assert time.monotonic() < end, f"not landed: {pilot.statustexts[-8:]}"
        for m in pilot.poll(0.5):
            if m.get_type() == "HEARTBEAT" and not m.base_mode & 128 and airborne.is_set():
                return
        if pilot.samples and pilot.samples[-1].alt_amsl_m > GROUND_M + 20.0:
            airborne.set()


def _closest(pilot: PilotLink, intruder_amsl_m: float) -> tuple[float, float]:
    """The plane's closest approach to the intruder against its minima (horizontal,
    vertical)."""
    ie, in_ = INTRUDER_EN_M
    hv = [
        (math.hypot(e - ie, n - in_), abs(s.alt_amsl_m - intruder_amsl_m))
        for s in pilot.samples
        for e, n in [local_m(LAT0, LON0, s.lat_deg, s.lon_deg)]
    ]
    return min(hv, key=lambda x: max(x[0] / INTRUDER_H_M, x[1] / INTRUDER_V_M))
