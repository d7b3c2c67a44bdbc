"""An independent ground station for tests: the pilot's own GCS beside gcs-utm.

PX4 instance i also talks MAVLink from UDP 14580+i to 14540+i (its onboard/API link), and
ArduPilot instance i serves MAVLink on TCP 5760+10i (SERIAL0) and 5762+10i (SERIAL1), so a test
can fly the vehicle (upload the operator's mission, arm, start it) and read the autopilot's own
positions on one link while gcs-utm holds another (PX4: 14550; ArduPilot: SERIAL1). Written
with raw pymavlink, sharing nothing with ``adapters.mavlink``: a bug there cannot hide in the
measurement. Blocking calls: run it beside a ``gcs-utm`` subprocess, or in a thread.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import struct
import time
from dataclasses import dataclass, field
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mav

EARTH_RADIUS_M = 6_371_008.8

# The links not closed yet, by id: a test that fails between opening and closing one leaves
# it to the autopilot fixtures, which close it (an open socket found later by the garbage
# collector is a ResourceWarning, an error in whichever test happens to run then).
_OPEN: dict[int, PilotLink] = {}


def close_open_links() -> int:
    """Close every link still open; how many there were."""
    links = list(_OPEN.values())
    for link in links:
        link.close()
    return len(links)


def offset_deg(
    lat_deg: float, lon_deg: float, east_m: float, north_m: float
) -> tuple[float, float]:
    """The point ``east_m``/``north_m`` from (lat_deg, lon_deg) on a local tangent plane."""
    dlat = math.degrees(north_m / EARTH_RADIUS_M)
    dlon = math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(lat_deg))))
    return lat_deg + dlat, lon_deg + dlon


def local_m(lat0: float, lon0: float, lat: float, lon: float) -> tuple[float, float]:
    """(east_m, north_m) of (lat, lon) from (lat0, lon0), local tangent plane."""
    north = math.radians(lat - lat0) * EARTH_RADIUS_M
    east = math.radians(lon - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    return east, north


@dataclass
class Sample:
    """One GLOBAL_POSITION_INT as PX4 reported it (host receipt time)."""

    t_s: float
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float


@dataclass
class PilotLink:
    """The pilot's GCS on PX4 instance ``instance``'s API link (``autopilot="px4"``) or on
    ArduPilot instance ``instance``'s SERIAL0 (``autopilot="ardupilot"``, TCP)."""

    instance: int
    autopilot: str = "px4"
    tcp_port: int | None = None  # ArduPilot: default SERIAL0, 5760+10i
    sock: socket.socket = field(init=False)
    enc: Any = field(init=False)
    dec: Any = field(init=False)
    samples: list[Sample] = field(default_factory=list)
    mission_current: list[tuple[float, int, int]] = field(default_factory=list)
    statustexts: list[str] = field(default_factory=list)
    home: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.autopilot == "px4":
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind(("127.0.0.1", 14540 + self.instance))
        else:
            port = self.tcp_port or 5760 + 10 * self.instance
            self.sock = socket.create_connection(("127.0.0.1", port), 10.0)
        _OPEN[id(self)] = self
        self.sock.settimeout(0.05)
        self.enc = mav.MAVLink(None, srcSystem=254, srcComponent=191)
        self.dec = mav.MAVLink(None)
        self.dec.robust_parsing = True

    @property
    def sys_id(self) -> int:
        return self.instance + 1

    def close(self) -> None:
        _OPEN.pop(id(self), None)
        self.sock.close()

    def send(self, msg: Any) -> None:
        if self.autopilot == "px4":
            self.sock.sendto(msg.pack(self.enc), ("127.0.0.1", 14580 + self.instance))
        else:
            self.sock.sendall(msg.pack(self.enc))

    def request_streams(self, rate_hz: int = 10) -> None:
        """ArduPilot sends nothing but HEARTBEAT until asked (all streams at ``rate_hz``)."""
        self.send(mav.MAVLink_request_data_stream_message(self.sys_id, 1, 0, rate_hz, 1))

    def poll(self, duration_s: float = 0.0) -> list[Any]:
        """Read what arrived (for ``duration_s`` at least once), keeping positions and
        MISSION_CURRENT; returns the messages."""
        out: list[Any] = []
        end = time.monotonic() + duration_s
        while True:
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                data = b""
            for m in self.dec.parse_buffer(data) or [] if data else []:
                if m.get_srcSystem() != self.sys_id:
                    continue
                out.append(m)
                self._keep(m)
            if time.monotonic() >= end:
                return out

    def _keep(self, m: Any) -> None:
        kind = m.get_type()
        now = time.monotonic()
        if kind == "GLOBAL_POSITION_INT" and m.lat != 0:
            self.samples.append(Sample(now, m.lat / 1e7, m.lon / 1e7, m.alt / 1000.0))
        elif kind == "MISSION_CURRENT":
            self.mission_current.append((now, int(m.seq), int(getattr(m, "total", 0) or 0)))
        elif kind == "STATUSTEXT":
            self.statustexts.append(str(m.text))
        elif kind == "HOME_POSITION":
            self.home = (m.latitude / 1e7, m.longitude / 1e7, m.altitude / 1000.0)

    def wait(self, kind: str, timeout_s: float, pred: Any = None) -> Any:
        """The first ``kind`` message (matching ``pred``) within ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for m in self.poll():
                if m.get_type() == kind and (pred is None or pred(m)):
                    return m
        raise TimeoutError(f"{self.autopilot} {self.sys_id}: no {kind} within {timeout_s} s")

    def wait_ready(self, timeout_s: float = 60.0) -> None:
        """Until the autopilot has a position fix and a home."""
        end = time.monotonic() + timeout_s
        while True:
            if self.autopilot != "px4":
                # ArduPilot ignores a stream request sent while it is still booting: repeat it
                self.request_streams()
            try:
                self.wait("GLOBAL_POSITION_INT", 2.0, lambda m: m.lat != 0)
                break
            except TimeoutError:
                if time.monotonic() >= end:
                    raise
        end = time.monotonic() + timeout_s
        while self.home is None and time.monotonic() < end:
            self.send(
                mav.MAVLink_command_long_message(self.sys_id, 1, 512, 0, 242, 0, 0, 0, 0, 0, 0)
            )
            self.poll(0.3)
        if self.home is None:
            raise TimeoutError(
                f"{self.autopilot} {self.sys_id}: no HOME_POSITION within {timeout_s} s"
            )

    def set_params(self, params: dict[str, float | int], timeout_s: float = 5.0) -> None:
        """PARAM_SET each (an int as MAV_PARAM_TYPE_INT32, its bits in the float, as PX4 and
        QGC encode it; a float as REAL32) and check the PARAM_VALUE echo."""
        for name, value in params.items():
            if isinstance(value, int):
                wire = struct.unpack("<f", struct.pack("<i", value))[0]
                kind = mav.MAV_PARAM_TYPE_INT32
            else:
                wire, kind = float(value), mav.MAV_PARAM_TYPE_REAL32
            echo = None
            end = time.monotonic() + timeout_s
            while echo is None:  # resent each second: a datagram can be lost
                msg = mav.MAVLink_param_set_message(self.sys_id, 1, name.encode(), wire, kind)
                self.send(msg)
                with contextlib.suppress(TimeoutError):
                    echo = self.wait("PARAM_VALUE", 1.0, lambda m, n=name: m.param_id == n)
                if echo is None and time.monotonic() > end:
                    raise TimeoutError(f"{self.autopilot} {self.sys_id}: {name} not echoed")
            if echo.param_value != wire and not (math.isnan(wire) and math.isnan(echo.param_value)):
                got = echo.param_value
                raise AssertionError(f"{self.autopilot} {self.sys_id}: {name} is {got}")

    def upload(self, items: list[Any], timeout_s: float = 10.0) -> None:
        """MISSION_COUNT, answer each request with MISSION_ITEM_INT, expect an accepted ACK."""
        self.send(mav.MAVLink_mission_count_message(self.sys_id, 1, len(items), 0))
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for m in self.poll():
                kind = m.get_type()
                if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                    self.send(items[m.seq])
                elif kind == "MISSION_ACK":
                    if m.type != 0:
                        raise AssertionError(
                            f"{self.autopilot} {self.sys_id} refused the mission: {m.type}"
                        )
                    return
        raise TimeoutError(f"{self.autopilot} {self.sys_id}: mission upload timed out")

    def command(self, command: int, *params: float, timeout_s: float = 5.0) -> int:
        """COMMAND_LONG (resent every 0.5 s) -> the COMMAND_ACK result."""
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.send(mav.MAVLink_command_long_message(self.sys_id, 1, command, 0, *p))
            stop = time.monotonic() + 0.5
            while time.monotonic() < stop:
                for m in self.poll():
                    if m.get_type() == "COMMAND_ACK" and m.command == command:
                        return int(m.result)
        raise TimeoutError(f"{self.autopilot} {self.sys_id}: no COMMAND_ACK for {command}")

    def arm_and_start(
        self, timeout_s: float = 60.0, takeoff_agl_m: float = 30.0, *, auto: bool = True
    ) -> None:
        """Arm (retrying while preflight checks refuse) and start the mission. ArduCopter
        arms in GUIDED, takes off to ``takeoff_agl_m`` and is switched to AUTO there; with
        ``auto=False`` it hovers in GUIDED until the caller sends ``set_mode(3)``, so that
        several copters can start their missions together."""
        if self.autopilot != "px4":
            self.set_mode(4)  # GUIDED
        self._arm(timeout_s)
        if self.autopilot == "px4":
            result = self.command(mav.MAV_CMD_MISSION_START, 0.0, 0.0)
            if result != mav.MAV_RESULT_ACCEPTED:
                raise AssertionError(f"PX4 {self.sys_id} refused MISSION_START ({result})")
            return
        cmd = mav.MAV_CMD_NAV_TAKEOFF
        result = self.command(cmd, 0, 0, 0, 0, 0, 0, takeoff_agl_m)
        if result != mav.MAV_RESULT_ACCEPTED:
            raise AssertionError(f"ArduPilot {self.sys_id} refused TAKEOFF ({result})")
        self.wait(
            "GLOBAL_POSITION_INT",
            timeout_s,
            lambda m: m.relative_alt / 1000.0 > 0.9 * takeoff_agl_m,
        )
        if auto:
            self.set_mode(3)  # AUTO

    def set_mode(self, custom_mode: int) -> None:
        """DO_SET_MODE with a custom mode number (ArduPilot: 3 AUTO, 4 GUIDED, 17 BRAKE)."""
        result = self.command(mav.MAV_CMD_DO_SET_MODE, 1.0, float(custom_mode))
        if result != mav.MAV_RESULT_ACCEPTED:
            raise AssertionError(f"{self.autopilot} {self.sys_id} refused mode {custom_mode}")

    def _arm(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        result = -1
        while time.monotonic() < end:
            result = self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
            if result == mav.MAV_RESULT_ACCEPTED:
                return
            self.poll(1.0)
        raise AssertionError(
            f"{self.autopilot} {self.sys_id} refused to arm ({result}): {self.statustexts[-5:]}"
        )


def mission_items(
    sys_id: int,
    start: tuple[float, float],
    waypoints: list[tuple[float, float, float]],
    *,
    autopilot: str = "px4",
) -> list[Any]:
    """The operator's mission: take off above ``start`` to the first waypoint's altitude, then
    the waypoints (lat_deg, lon_deg, alt). PX4: MAV_FRAME_GLOBAL_INT, alt in metres AMSL.
    ArduPilot: seq 0 is home (``start``), then MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, alt in
    metres above home, as its ground stations send it."""
    ardupilot = autopilot != "px4"
    frame = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT if ardupilot else mav.MAV_FRAME_GLOBAL_INT

    def item(seq: int, command: int, lat: float, lon: float, alt: float, hold_s: float) -> Any:
        return mav.MAVLink_mission_item_int_message(
            sys_id, 1, seq, frame, command, 0, 1, hold_s, 2.0, 0, math.nan,
            round(lat * 1e7), round(lon * 1e7), alt, 0,
        )  # fmt: skip

    items = []
    if ardupilot:
        items.append(item(0, mav.MAV_CMD_NAV_WAYPOINT, *start, 0.0, 0.0))
    items.append(item(len(items), mav.MAV_CMD_NAV_TAKEOFF, *start, waypoints[0][2], 0.0))
    for lat, lon, alt in waypoints:
        items.append(item(len(items), mav.MAV_CMD_NAV_WAYPOINT, lat, lon, alt, 0.0))
    return items
