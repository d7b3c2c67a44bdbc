"""The real autopilots start from ../shared and talk MAVLink on their documented ports."""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.autopilot.autopilots import SitlProcess, wait_tcp_listening


def _first(sock: socket.socket, kind: str, timeout_s: float, recv: Callable[[], bytes]) -> object:
    dec = mav.MAVLink(None)
    dec.robust_parsing = True
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            data = recv()
        except TimeoutError:
            continue
        for m in dec.parse_buffer(data) or []:
            if m.get_type() == kind:
                return m
    raise AssertionError(f"no {kind} within {timeout_s} s")


@pytest.mark.load_tolerant  # one HEARTBEAT within 20 s: beside the rest (docs/testing.md)
def test_px4_heartbeat_on_gcs_port(px4: Callable[..., SitlProcess]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 14550))
        s.settimeout(0.5)
        p = px4(instance=1, airframe="quad", speed=5.0)
        hb = _first(s, "HEARTBEAT", 20.0, lambda: s.recvfrom(65536)[0])
        assert p.alive
        assert hb.get_srcSystem() == 2  # type: ignore[attr-defined]
        assert hb.autopilot == mav.MAV_AUTOPILOT_PX4  # type: ignore[attr-defined]


def test_ardupilot_heartbeat_on_tcp(ardupilot: Callable[..., SitlProcess]) -> None:
    p = ardupilot(instance=0, vehicle="copter", speed=5.0)
    wait_tcp_listening(5760)
    with socket.create_connection(("127.0.0.1", 5760), timeout=5.0) as s:
        s.settimeout(0.5)
        hb = _first(s, "HEARTBEAT", 20.0, lambda: s.recv(65536))
    assert p.alive
    assert hb.get_srcSystem() == 1  # type: ignore[attr-defined]
    assert hb.autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA  # type: ignore[attr-defined]
