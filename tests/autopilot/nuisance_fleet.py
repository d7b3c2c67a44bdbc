"""The four vehicles of the nuisance soak (nuisance.py) and the link it can cut.

Each vehicle is a real autopilot from ``../shared`` flown by its own pilot (pilot.py, the
pilot's GCS on the autopilot's other link) in a thread: upload the mission, arm, start it,
follow it to touchdown and disarm, rest on the ground, again. The missions are normal
ones, each a few minutes long: a take-off, waypoints, a loiter and a landing.

- PX4 SIH quad (instance 0, sysid 1) at the origin: up to 30 m, a 200 m triangle, a 20 s
  loiter, a landing at home;
- PX4 SIH plane (instance 1, sysid 2) 2.5 km east: a runway take-off north to 30 m, 700 m
  north at 40 m, a 20 s loiter 300 m west, then an approach and NAV_LAND 300 m south of
  home (lands and disarms on its own);
- ArduCopter (instance 2, sysid 3) 2.5 km south: the same shape as the PX4 quad, ending in
  NAV_LAND at home;
- ArduPlane (instance 3, sysid 4) 3 km west: the mission of test_plane_takeoff.py (take-off
  north, 1600 m north, 800 m west, DO_LAND_START, approach, NAV_LAND at home).

They are kilometres apart: no pair can come near another, so no separation threat is a
true one. ``TcpCut`` stands between gcs-utm and the ArduCopter's SERIAL1: it forwards
bytes both ways until cut, then drops them (the sockets stay open, as a radio out of range).
"""

from __future__ import annotations

import contextlib
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.autopilot.autopilots import (
    PX4_DEFAULT_HOME,
    PX4_SIH_PLANE_PARAMS,
    SitlProcess,
    start_ardupilot,
    start_px4,
    wait_tcp_listening,
)
from tests.autopilot.pilot import PilotLink, offset_deg

ORIGIN = PX4_DEFAULT_HOME  # lat, lon, ground AMSL m: every vehicle's home is on this ground
ARDUPILOT_AUTO = {"copter": 3, "plane": 10}  # custom modes
BATTERY_RESET = 42651  # MAV_CMD_BATTERY_RESET (ArduPilot): battery mask, percentage


def _home(east_m: float, north_m: float) -> tuple[float, float]:
    return offset_deg(ORIGIN[0], ORIGIN[1], east_m, north_m)


@dataclass(frozen=True)
class VehicleDef:
    """One vehicle of the soak: its autopilot, airframe, instance and home offset."""

    name: str
    autopilot: str  # "px4" or "ardupilot"
    airframe: str  # "quad"/"plane" (PX4), "copter"/"plane" (ArduPilot)
    instance: int
    east_m: float
    north_m: float

    @property
    def sys_id(self) -> int:
        return self.instance + 1

    @property
    def home(self) -> tuple[float, float]:
        return _home(self.east_m, self.north_m)

    @property
    def serial1_port(self) -> int:
        """ArduPilot SERIAL1 (TCP), gcs-utm's link."""
        return 5762 + 10 * self.instance


VEHICLES = (
    VehicleDef("px4-quad", "px4", "quad", 0, 0.0, 0.0),
    VehicleDef("px4-plane", "px4", "plane", 1, 2500.0, 0.0),
    VehicleDef("arducopter", "ardupilot", "copter", 2, 0.0, -2500.0),
    VehicleDef("arduplane", "ardupilot", "plane", 3, -3000.0, 0.0),
)


def _item(
    v: VehicleDef, seq: int, cmd: int, east: float, north: float, agl_m: float, p1: float = 0.0
) -> Any:
    """A MISSION_ITEM_INT ``east``/``north`` metres from the vehicle's home, ``agl_m`` above
    it: PX4 in AMSL (MAV_FRAME_GLOBAL_INT), ArduPilot above home (RELATIVE_ALT), as their
    ground stations send them."""
    lat, lon = offset_deg(*v.home, east, north)
    if v.autopilot == "px4":  # param 4 (yaw) NaN: PX4 keeps its own heading
        frame, alt, p4 = mav.MAV_FRAME_GLOBAL_INT, ORIGIN[2] + agl_m, float("nan")
    else:  # ArduCopter refuses a NaN in LOITER_TIME and LAND
        frame, alt, p4 = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, agl_m, 0.0
    return mav.MAVLink_mission_item_int_message(
        v.sys_id, 1, seq, frame, cmd, 0, 1, p1, 0.0, 0.0, p4,
        round(lat * 1e7), round(lon * 1e7), alt, 0,
    )  # fmt: skip


def mission(v: VehicleDef) -> list[Any]:
    """The vehicle's normal mission (see the module docstring)."""
    takeoff, wp, land = mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LAND
    loiter = mav.MAV_CMD_NAV_LOITER_TIME
    if v.airframe in ("quad", "copter"):
        legs = [
            (takeoff, 0.0, 0.0, 30.0, 0.0),
            (wp, 0.0, 200.0, 30.0, 0.0),
            (wp, 150.0, 100.0, 35.0, 0.0),
            (loiter, 150.0, 100.0, 35.0, 20.0),
            (wp, 0.0, 0.0, 30.0, 0.0),
            (land, 0.0, 0.0, 0.0, 0.0),
        ]
    elif v.autopilot == "px4":  # the SIH plane: take-off towards 250 m north
        legs = [
            (takeoff, 0.0, 250.0, 30.0, 15.0),
            (wp, 0.0, 700.0, 40.0, 0.0),
            (loiter, -300.0, 700.0, 40.0, 20.0),
            (wp, -300.0, 300.0, 30.0, 0.0),
            (land, 0.0, -300.0, 0.0, 0.0),
        ]
    else:  # ArduPlane: as tests/autopilot/test_plane_takeoff.py
        legs = [
            (takeoff, 0.0, 0.0, 30.0, 15.0),
            (wp, 0.0, 1600.0, 60.0, 0.0),
            (loiter, -800.0, 1600.0, 60.0, 20.0),
            (mav.MAV_CMD_DO_LAND_START, -800.0, 0.0, 0.0, 0.0),
            (wp, -400.0, -400.0, 30.0, 0.0),
            (land, 0.0, 0.0, 0.0, 0.0),
        ]
    items = [_item(v, 0, wp, 0.0, 0.0, 0.0)] if v.autopilot == "ardupilot" else []
    for cmd, east, north, agl, p1 in legs:
        items.append(_item(v, len(items), cmd, east, north, agl, p1))
    if v.autopilot == "ardupilot" and v.airframe == "copter":
        items[1].x = items[1].y = 0  # NAV_TAKEOFF where it stands
    return items


class TcpCut:
    """A TCP relay from ``listen_port`` to ``upstream_port`` on 127.0.0.1 (a thread). While
    ``cut`` is set, bytes in both directions are read and dropped; the connections stay
    open. Each accepted client gets its own upstream connection."""

    def __init__(self, listen_port: int, upstream_port: int) -> None:
        self.upstream_port = upstream_port
        self.cut = threading.Event()
        self.dropped_bytes = 0
        self._stop = threading.Event()
        self._server = socket.create_server(("127.0.0.1", listen_port))
        self._server.setblocking(False)
        self._sel = selectors.DefaultSelector()
        self._sel.register(self._server, selectors.EVENT_READ, None)
        self._thread = threading.Thread(target=self._run, name="tcp-cut", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                for key, _ in self._sel.select(0.1):
                    if key.data is None:
                        self._accept()
                    else:
                        self._forward(key.fileobj, key.data)  # type: ignore[arg-type]
        finally:
            for key in list(self._sel.get_map().values()):
                with contextlib.suppress(OSError):
                    key.fileobj.close()  # type: ignore[union-attr]
            self._sel.close()

    def _accept(self) -> None:
        client, _ = self._server.accept()
        try:
            up = socket.create_connection(("127.0.0.1", self.upstream_port), 5.0)
        except OSError:
            client.close()
            return
        for a, b in ((client, up), (up, client)):
            a.setblocking(False)
            self._sel.register(a, selectors.EVENT_READ, b)

    def _forward(self, src: socket.socket, dst: socket.socket) -> None:
        try:
            data = src.recv(65536)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:  # one side closed: close the pair
            for s in (src, dst):
                with contextlib.suppress(KeyError, ValueError):
                    self._sel.unregister(s)
                s.close()
            return
        if self.cut.is_set():
            self.dropped_bytes += len(data)
            return
        with contextlib.suppress(OSError):
            dst.setblocking(True)
            dst.sendall(data)
            dst.setblocking(False)


@dataclass
class Flyer:
    """One vehicle flown in cycles by its pilot (``run`` in a thread until ``stop``)."""

    v: VehicleDef
    root: Path
    speed: float
    rest_s: float  # simulated seconds on the ground between flights
    log: Callable[[str], None]
    proc: SitlProcess | None = None
    pilot: PilotLink | None = None
    flights: int = 0  # landed
    takeoffs: int = 0
    airborne: bool = False
    reboot_after_landing: bool = False  # a process restart at its next landing (once)
    rebooted_at: list[float] = field(default_factory=list)  # wall monotonic s
    stop: threading.Event = field(default_factory=threading.Event)
    go: threading.Event = field(default_factory=threading.Event)  # the first take-off
    land_before_stop: bool = True  # when stopped in flight, fly on to the landing
    error: str = ""
    armed: bool = False
    all_procs: list[SitlProcess] = field(default_factory=list)

    @property
    def workdir(self) -> Path:
        return self.root / self.v.name

    def boot(self) -> None:
        """Start the autopilot (again, on the same working directory) and the pilot's link."""
        if self.v.autopilot == "px4":
            self.proc = start_px4(
                self.root, instance=self.v.instance, airframe=self.v.airframe,
                home=self.v.home, speed=self.speed, workdir=self.workdir,
            )  # fmt: skip
            if self.pilot is None:
                self.pilot = PilotLink(self.v.instance)
        else:
            home = (*self.v.home, ORIGIN[2], 0.0)  # heading 0: the runway points north
            self.proc = start_ardupilot(
                self.root, instance=self.v.instance, vehicle=self.v.airframe, home=home,
                speed=self.speed, workdir=self.workdir,
            )  # fmt: skip
            wait_tcp_listening(5760 + 10 * self.v.instance, 30.0)
            self.pilot = PilotLink(self.v.instance, autopilot="ardupilot")
        self.all_procs.append(self.proc)
        self.pilot.wait_ready(120.0)
        if self.v.autopilot == "px4" and self.v.airframe == "plane":
            self.pilot.set_params(PX4_SIH_PLANE_PARAMS)
        if self.v.autopilot == "ardupilot" and self.v.airframe == "plane":
            # RTL_AUTOLAND: it arms with DO_LAND_START only with it; FLIGHT_OPTIONS bit 14:
            # climb first to a higher waypoint (docs/autopilots.md)
            self.pilot.set_params({"RTL_AUTOLAND": 2.0, "FLIGHT_OPTIONS": 16384.0})
        if not self.all_procs[:-1]:  # the first boot: the operator's mission is on board
            self._upload()

    def shutdown(self) -> None:
        if self.pilot is not None:
            self.pilot.close()
            self.pilot = None
        for p in self.all_procs:
            p.stop()

    def run(self) -> None:
        try:
            while not self.go.is_set() and not self.stop.is_set():
                self._poll(0.5)
            while not self.stop.is_set():
                self._fly_once()
                if self.stop.is_set():
                    break
                if self.reboot_after_landing:
                    self.reboot_after_landing = False
                    self._reboot()
                self._rest(self.rest_s / self.speed)
        except Exception as exc:  # reported by the soak, which fails on it
            self.error = f"{self.v.name}: {type(exc).__name__}: {exc}"
            self.log(self.error)

    def _reboot(self) -> None:
        """A power cycle on the ground: the process stopped and started on the same
        working directory (parameters, mission), the pilot's link reopened."""
        assert self.proc is not None and self.pilot is not None
        self.log(f"{self.v.name}: reboot (process restart)")
        self.rebooted_at.append(time.monotonic())
        if self.v.autopilot == "ardupilot":
            self.pilot.close()
            self.pilot = None
        self.proc.stop()
        if self.pilot is not None:  # PX4: the same socket; what the old life sent is stale
            self.pilot.poll(0.5)
            self.pilot.home = None
        self.boot()
        self.log(f"{self.v.name}: back after the reboot")

    def _poll(self, duration_s: float) -> None:
        assert self.pilot is not None
        if self.v.autopilot == "ardupilot":
            self.pilot.request_streams()
        for m in self.pilot.poll(duration_s):
            if m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1:
                self.armed = bool(m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    def _rest(self, wall_s: float) -> None:
        end = time.monotonic() + wall_s
        while time.monotonic() < end and not self.stop.is_set():
            self._poll(0.5)

    def _upload(self) -> None:
        assert self.pilot is not None
        for attempt in range(5):  # PX4's transfer timeouts run on its clock
            try:
                self.pilot.upload(mission(self.v))
                return
            except (TimeoutError, AssertionError):
                if attempt == 4:
                    raise
                self.pilot.poll(1.0)

    def _fly_once(self) -> None:
        if self.takeoffs:  # again: the pilot uploads the mission for the next flight
            self._upload()
            self._fresh_battery()
        if self.stop.is_set():
            return
        self._start()
        self.takeoffs += 1
        self.airborne = True
        self.log(f"{self.v.name}: take-off {self.takeoffs}")
        # the longest mission (ArduPlane, 5.6 km) takes about 330 simulated s
        end = time.monotonic() + 3.0 * 600.0 / self.speed
        self.armed = True
        while self.armed:
            if self.stop.is_set() and not self.land_before_stop:
                return  # the soak is over and does not wait for the landing
            if time.monotonic() > end:
                raise TimeoutError(f"no landing in {3 * 600} simulated s")
            self._poll(0.5)
        self.airborne = False
        self.flights += 1
        self.log(f"{self.v.name}: landed {self.flights}")

    def _fresh_battery(self) -> None:
        """A charged battery for the next flight, as a pilot swaps it: ArduPilot SITL's
        battery drains flight after flight (the ArduCopter of the 30-minute soak reported
        24 % in its fourth flight: LACK_OF_BATTERY, a true alarm); MAV_CMD_BATTERY_RESET
        sets its remaining charge (every battery, 100 %). PX4 SIH's simulated battery
        stops draining at 50 % (SIM_BAT_MIN_PCT)."""
        if self.v.autopilot == "ardupilot":
            assert self.pilot is not None
            self.pilot.command(BATTERY_RESET, 255.0, 100.0)

    def _start(self) -> None:
        assert self.pilot is not None
        p = self.pilot
        if self.v.autopilot == "px4":
            p.arm_and_start(120.0)
            return
        # from the first item, whatever an earlier flight left current
        p.send(mav.MAVLink_mission_set_current_message(self.v.sys_id, 1, 1))
        if self.v.airframe == "copter":
            p.arm_and_start(120.0, takeoff_agl_m=30.0)  # GUIDED take-off, then AUTO
        else:
            p.set_mode(ARDUPILOT_AUTO["plane"])
            p._arm(120.0)
