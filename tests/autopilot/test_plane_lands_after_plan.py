"""Issue 31.4 on real ArduPlane: a plane that takes off from its runway, meets an intruder and
flies the plan ``serve --auto-accept`` uploads ends on the pilot's own landing sequence.

An ArduPlane 4.6 SITL (speed 5) holds the pilot's mission: a runway take-off (15 deg to
30 m), 1500 m north climbing to 60 m, 600 m west, then DO_LAND_START, an approach 700 m
south descending to 30 m and NAV_LAND 600 m west of home: the landing point is not home, so
a plane that returned home, circled the plan's end or landed anywhere else is told apart.
``gcs-utm serve --headless --auto-accept`` watches it on SERIAL1 and reads an SBS-1 feed
(the test's dump1090): once the plane is airborne a hovering helicopter appears 1000 m north
of home at the plane's cruise altitude, on its first leg. Serve predicts the INTRUDER
threat, decides (vertical or lateral avoidance), and uploads the plan; the plane flies it
and then lands. Checked against the plane's own positions and mission (the pilot's link,
SERIAL0, sharing nothing with ``adapters.mavlink``): a recommendation applied and its upload
on the plane (the mission read back is not the pilot's); the intruder minima (150 m / 50 m)
kept throughout; the mission read back after touchdown ends with the pilot's DO_LAND_START,
approach and NAV_LAND, item for item as uploaded; the plane touched down on that NAV_LAND
near the pilot's landing point, not near home.
"""

from __future__ import annotations

import contextlib
import math
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mav

from tests.adsb.sbs_lines import sbs_position, sbs_velocity
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess, wait_tcp_listening
from tests.autopilot.closed_loop import Crossing, _config, rows, serve_process
from tests.autopilot.pilot import PilotLink, local_m, offset_deg
from tests.autopilot.test_plane_takeoff import AUTO, _download

SPEED = 5.0  # ArduPlane --speedup; serve --speed matches it
CRUISE_ALT_M = 60.0  # above home
LANDING_EN_M = (-600.0, 0.0)  # the pilot's NAV_LAND, east/north of home
INTRUDER_EN_M = (0.0, 1000.0)  # the helicopter, on the first leg at the cruise altitude
INTRUDER_ICAO = "4CA7E1"
FEED_HZ = 5.0  # SBS lines a wall second: about one a simulated second at speed 5
INTRUDER_H_M, INTRUDER_V_M = 150.0, 50.0  # [monitoring] intruder minima
TOUCHDOWN_M = 150.0
"""The plane touches down this close to its NAV_LAND point: ArduPlane glides onto it from the
approach and rolls on past it (measured 30-40 m past it in the take-off tests)."""
FLIGHT_S = 320.0  # simulated: about 4.5 km at 22-24 m/s, the take-off, avoidance and landing


def _mission(lat0: float, lon0: float) -> list[Any]:
    """Home, NAV_TAKEOFF (15 deg, 30 m), 1500 m north climbing to 60 m, 600 m west at 60 m,
    DO_LAND_START, the approach 700 m south descending to 30 m, NAV_LAND 600 m west of home
    (altitudes above home, as ground stations send them)."""
    rel = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT

    def item(seq: int, cmd: int, east: float, north: float, alt: float) -> Any:
        lat, lon = offset_deg(lat0, lon0, east, north)
        return mav.MAVLink_mission_item_int_message(
            1, 1, seq, rel, cmd, 0, 1, 0.0, 0.0, 0.0, 0.0, round(lat * 1e7), round(lon * 1e7),
            alt, 0,
        )  # fmt: skip

    takeoff = mav.MAVLink_mission_item_int_message(
        1, 1, 1, rel, mav.MAV_CMD_NAV_TAKEOFF, 0, 1, 15.0, 0, 0, 0, 0, 0, 30.0, 0
    )
    east, north = LANDING_EN_M
    return [
        item(0, mav.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0),
        takeoff,
        item(2, mav.MAV_CMD_NAV_WAYPOINT, 0.0, 1500.0, CRUISE_ALT_M),
        item(3, mav.MAV_CMD_NAV_WAYPOINT, east, 1500.0, CRUISE_ALT_M),
        item(4, mav.MAV_CMD_DO_LAND_START, east, 700.0, 0.0),
        item(5, mav.MAV_CMD_NAV_WAYPOINT, east, north + 700.0, 30.0),
        item(6, mav.MAV_CMD_NAV_LAND, east, north, 0.0),
    ]


def hovering_intruder(
    lat_deg: float, lon_deg: float, amsl_m: float, airborne: threading.Event
) -> Callable[[], list[str] | None]:
    """The intruder's SBS-1 lines for :func:`_sbs_feed`: a helicopter hovering at the given
    place and altitude, heard only once ``airborne`` is set (the plane is up)."""

    def lines() -> list[str] | None:
        if not airborne.is_set():
            return None
        alt_ft = amsl_m / 0.3048
        return [
            sbs_position(INTRUDER_ICAO, lat_deg, lon_deg, alt_ft),
            sbs_velocity(INTRUDER_ICAO, 0.0, 0.0, 0.0),
        ]

    return lines


def adsb_config(port: int) -> str:
    """The ``[adsb]`` table of serve's configuration reading :func:`_sbs_feed` on ``port``
    (capture time: the receipt, on serve's clock)."""
    return (
        f'\n[adsb]\nenabled = true\nhost = "127.0.0.1"\nsbs_port = {port}\n'
        "sbs_times_are_utc = false\nreconnect_max_s = 1.0\n"
    )


@contextlib.contextmanager
def _sbs_feed(line: Callable[[], list[str] | None]) -> Iterator[int]:
    """A dump1090-style SBS-1 server on 127.0.0.1 (an ephemeral port, yielded): every client
    gets ``line()``'s lines :data:`FEED_HZ` times a wall second (None: nothing yet)."""
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(0.2)
    stop = threading.Event()

    def client(conn: socket.socket) -> None:
        with conn:
            while not stop.is_set():
                lines = line()
                if lines:
                    try:
                        conn.sendall("".join(f"{x}\r\n" for x in lines).encode())
                    except OSError:
                        return
                stop.wait(1.0 / FEED_HZ)

    def accept() -> None:
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            threading.Thread(target=client, args=(conn,), daemon=True).start()

    acceptor = threading.Thread(target=accept, daemon=True)
    acceptor.start()
    try:
        yield int(server.getsockname()[1])
    finally:
        stop.set()
        acceptor.join(timeout=5.0)
        server.close()


def _on_landing(pilot: PilotLink, ground_amsl_m: float) -> bool:
    """On its mission's last item (NAV_LAND: ArduPilot's MISSION_CURRENT ``total`` counts
    the items after home, so the last is ``seq == total``) and standing on the ground (within
    1.5 m of home's altitude, its last four positions within 1 m of each other)."""
    if not pilot.mission_current:
        return False
    _, seq, total = pilot.mission_current[-1]
    last = pilot.samples[-4:]
    if seq < total or len(last) < 4 or last[-1].alt_amsl_m > ground_amsl_m + 1.5:
        return False
    east, north = local_m(last[0].lat_deg, last[0].lon_deg, last[-1].lat_deg, last[-1].lon_deg)
    return abs(east) + abs(north) < 1.0


def _same_item(a: Any, b: Any) -> bool:
    """Two MISSION_ITEM_INTs read back from the plane are the same item (command, frame,
    params, position, altitude)."""
    keys = ("command", "frame", "x", "y")
    params = ("param1", "param2", "param3", "param4", "z")
    return all(getattr(a, k) == getattr(b, k) for k in keys) and all(
        math.isclose(getattr(a, k), getattr(b, k), abs_tol=1e-3) for k in params
    )


@pytest.mark.timeout(300)
def test_arduplane_avoids_an_intruder_and_lands_on_its_own_landing(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, ground, _heading = ARDUPILOT_DEFAULT_HOME
    ardupilot(instance=0, vehicle="plane", speed=SPEED, home=(lat0, lon0, ground, 0.0))
    wait_tcp_listening(5760)
    pilot = PilotLink(0, autopilot="ardupilot")
    mission = _mission(lat0, lon0)
    ilat, ilon = offset_deg(lat0, lon0, *INTRUDER_EN_M)
    intruder_amsl_m = ground + CRUISE_ALT_M
    airborne = threading.Event()

    intruder = hovering_intruder(ilat, ilon, intruder_amsl_m, airborne)

    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    crossing = Crossing(origin=(lat0, lon0), ground_amsl_m=ground)
    try:
        pilot.wait_ready()
        # RTL_AUTOLAND: else "Arm: DO_LAND_START set and ..."; FLIGHT_OPTIONS bit 14
        # (IMMEDIATE_CLIMB_IN_AUTO): climb first to a higher waypoint, not on a glide slope
        pilot.set_params({"RTL_AUTOLAND": 2.0, "FLIGHT_OPTIONS": 16384.0})
        pilot.upload(mission)
        uploaded = _download(pilot)  # the pilot's mission as the plane holds it
        assert [int(it.command) for it in uploaded] == [int(it.command) for it in mission]
        with _sbs_feed(intruder) as port:
            cfg = _config(tmp_path / "serve.toml", crossing, ["tcp:127.0.0.1:5762"])
            cfg.write_text(cfg.read_text() + adsb_config(port))
            with serve_process(cfg, db, log_path, SPEED) as serve:
                _wait_filed(pilot, db, serve)
                pilot.set_mode(AUTO)
                pilot._arm(60.0)
                _fly(pilot, ground, airborne)
                got = _download(pilot)
                pilot.close()  # before serve stops (test_plane_takeoff.py)
    finally:
        pilot.close()
    tail = log_path.read_text(errors="replace")[-4000:]
    threats = [str(r[0]) for r in rows(db, "SELECT kind FROM threats")]
    assert "INTRUDER" in threats, f"no intruder threat: {threats}\n{tail}"
    recs = [str(r[0]) for r in rows(db, "SELECT state FROM recommendations")]
    assert "applied" in recs, f"no plan applied: {recs}\n{tail}"
    # the plane flew the uploaded plan: its mission is not the pilot's, and it kept the minima
    assert len(got) != len(uploaded) or not all(map(_same_item, got, uploaded)), "not replaced"
    _assert_kept_minima(pilot, lat0, lon0, intruder_amsl_m, airborne)
    # its mission ends with the pilot's landing sequence, item for item
    commands = [int(it.command) for it in got]
    assert len(got) >= 3 and all(map(_same_item, got[-3:], uploaded[-3:])), commands
    # and it touched down on that landing, not at home
    last = pilot.samples[-1]
    from_landing_m = math.hypot(
        *local_m(*offset_deg(lat0, lon0, *LANDING_EN_M), last.lat_deg, last.lon_deg)
    )
    from_home_m = math.hypot(*local_m(lat0, lon0, last.lat_deg, last.lon_deg))
    assert from_landing_m < TOUCHDOWN_M, f"landed {from_landing_m:.0f} m from its landing"
    assert from_home_m > 400.0, f"landed {from_home_m:.0f} m from home"


def _wait_filed(pilot: PilotLink, db: Path, serve: subprocess.Popen[bytes]) -> None:
    """Until serve has filed the plane's operation, reading the pilot's link meanwhile: left
    unread while serve starts (20 s and more at a load of 20 on 2 cores), its backlog held
    back the ACK of the pilot's next command beyond its 5 s."""
    end = time.monotonic() + 120.0
    while not rows(db, "SELECT id FROM operations"):
        assert serve.poll() is None, "gcs-utm serve exited early"
        assert time.monotonic() < end, "no operation filed after 120 s"
        pilot.poll(0.5)


def _fly(pilot: PilotLink, ground_amsl_m: float, airborne: threading.Event) -> None:
    """Follow the plane to touchdown on its landing (within twice :data:`FLIGHT_S`
    simulated), setting ``airborne`` 20 m above the ground."""
    end = time.monotonic() + 2.0 * FLIGHT_S / SPEED
    while not (airborne.is_set() and _on_landing(pilot, ground_amsl_m)):
        assert time.monotonic() < end, f"no touchdown: {pilot.statustexts[-8:]}"
        pilot.request_streams()
        pilot.poll(0.5)
        if pilot.samples and pilot.samples[-1].alt_amsl_m > ground_amsl_m + 20.0:
            airborne.set()


def _assert_kept_minima(
    pilot: PilotLink, lat0: float, lon0: float, intruder_amsl_m: float, airborne: threading.Event
) -> None:
    """No position of the plane inside the intruder minima (both at once)."""
    assert airborne.is_set(), "never airborne"
    ie, in_ = INTRUDER_EN_M
    worst = min(
        (
            (math.hypot(e - ie, n - in_), abs(s.alt_amsl_m - intruder_amsl_m))
            for s in pilot.samples
            for e, n in [local_m(lat0, lon0, s.lat_deg, s.lon_deg)]
        ),
        key=lambda hv: max(hv[0] / INTRUDER_H_M, hv[1] / INTRUDER_V_M),
    )
    score = max(worst[0] / INTRUDER_H_M, worst[1] / INTRUDER_V_M)
    assert score >= 1.0, f"inside the intruder minima: {worst[0]:.0f} m / {worst[1]:.0f} m"
