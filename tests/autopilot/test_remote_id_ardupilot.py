"""A real ArduCopter 4.6 SITL that enforces Remote ID arms under ``gcs-utm serve`` only once
gcs-utm supplies the operator's part.

ArduPilot (libraries/AP_OpenDroneID) with ``DID_ENABLE 1``, ``DID_OPTIONS 1`` (EnforceArming)
and ``DID_MAVPORT 1`` refuses to arm ("OpenDroneID: operator location must be set") until a
GCS sends OPEN_DRONE_ID_SYSTEM with the operator's location, needs a Basic ID, and needs an
OPEN_DRONE_ID_ARM_STATUS "good to arm" younger than 3 s from the transmitter on the
``DID_MAVPORT`` serial port. The test plays that transmitter (as ArduRemoteID does: component
236, ARM_STATUS at a steady rate) on SERIAL1 (TCP 5762); ArduPilot forwards what it gets from
the GCS to it, so the transmitter also shows that gcs-utm's operator location, serial number
and operator ID reached the autopilot.

Phase 1: no operation is filed and ``[remote_id]`` has no operator location: gcs-utm sends
Basic ID and Operator ID, no System; arming fails for exactly the Remote ID reason (once the
other pre-arm checks pass). Phase 2: an operation is filed for the vehicle; gcs-utm sends its
home as the operator location and the vehicle arms, takes off, and goes on receiving the
operator location in the air.

ArduPilot measures the 3 s in simulated time: at SPEED x, a period P of real time is P x SPEED
simulated, hence the shorter periods here (0.8 s simulated for both SYSTEM and ARM_STATUS).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig
from adapters.remoteid.config import RemoteIdConfig
from gcs_utm.app import Runtime
from gcs_utm.model import (
    FlightPlan,
    Operation,
    OperationId,
    OperationState,
    Position,
    SysId,
    TrackId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.settings import Settings
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import serve_while, until

pytestmark = [pytest.mark.slow, pytest.mark.network]

SPEED = 2.0
PERIOD_S = 0.4  # real seconds between SYSTEM (gcs-utm) and ARM_STATUS (transmitter)
SERIAL = "1596A303716531B"
OPERATOR_ID = "FIN87astrdge12k8"
RID_PARAMS = "DID_ENABLE 1\nDID_OPTIONS 1\nDID_MAVPORT 1\n"
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_COMP_ID_ODID_TXRX_1 = 236
MAV_TYPE_ODID = 34
ODID_REASON = "operator location must be set"
MAV_CMD_DO_SET_MODE = 176  # (1 = custom mode, ArduCopter 4 GUIDED / 9 LAND)
MAV_CMD_NAV_TAKEOFF = 22
TAKEOFF_AGL_M = 10.0


class Transmitter:
    """A Remote ID transmitter on ArduPilot's SERIAL1: ARM_STATUS good-to-arm every
    ``PERIOD_S`` and a heartbeat; keeps what ArduPilot sends it."""

    def __init__(self) -> None:
        self.mav = mav.MAVLink(None, srcSystem=1, srcComponent=MAV_COMP_ID_ODID_TXRX_1)
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.received: list[Any] = []

    async def run(self, port: int) -> None:
        reader, writer = await _connect(port)
        read = asyncio.create_task(self._read(reader))
        try:
            while True:
                writer.write(self.mav.heartbeat_encode(MAV_TYPE_ODID, 8, 0, 0, 4).pack(self.mav))
                writer.write(self.mav.open_drone_id_arm_status_encode(0, b"").pack(self.mav))
                await writer.drain()
                await asyncio.sleep(PERIOD_S)
        finally:
            read.cancel()
            writer.close()

    async def _read(self, reader: asyncio.StreamReader) -> None:
        while data := await reader.read(4096):
            self.received.extend(self.parser.parse_buffer(data) or [])

    def got(self, name: str) -> list[Any]:
        return [m for m in self.received if m.get_type() == name]


async def _connect(port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    for _ in range(200):
        with contextlib.suppress(OSError):
            return await asyncio.open_connection("127.0.0.1", port)
        await asyncio.sleep(0.1)
    raise AssertionError(f"nothing listens on TCP {port}")


class Texts:
    """The vehicle's STATUSTEXTs, read from the hub's raw tap."""

    def __init__(self) -> None:
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.lines: list[tuple[float, str]] = []

    def tap(self, link: str, data: bytes, t_s: float) -> None:
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "STATUSTEXT" and m.get_srcSystem() == 1:
                self.lines.append((time.monotonic(), str(m.text).rstrip("\x00")))

    def since(self, t0: float) -> list[str]:
        return [text for t, text in self.lines if t >= t0]


async def _arm(rt: Runtime, texts: Texts) -> tuple[bool, list[str]]:
    """One arming attempt: whether it was accepted, and the texts that came with it."""
    t0 = time.monotonic()
    res = await rt.hub.command_long(
        SysId(1), MAV_CMD_COMPONENT_ARM_DISARM, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    )
    await asyncio.sleep(0.5)
    return res.ok, texts.since(t0)


def _height_m(rt: Runtime, home: Position) -> float:
    """Height of the vehicle's track above the home (0 before there is a track)."""
    track = rt.tracks().get(TrackId("rid-1"))
    return 0.0 if track is None else track.alt_amsl_m - home.alt_amsl_m


def _operation(home: Position) -> Operation:
    oid = OperationId("rid-1")
    wp = Waypoint4D(
        lat_deg=home.lat_deg, lon_deg=home.lon_deg, alt_amsl_m=home.alt_amsl_m + 30.0, t_s=0.0
    )
    return Operation(
        id=oid,
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=FlightPlan(operation_id=oid, version=1, waypoints=(wp,)),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=20.0,
        operational_volume_m=50.0,
        home=home,
        state=OperationState.PLANNED,
    )


async def _refused_for_remote_id(rt: Runtime, texts: Texts) -> list[str]:
    """Arm until the only reason given is Remote ID's (other checks pass after ~20 s)."""
    deadline = time.monotonic() + 90.0
    while time.monotonic() < deadline:
        ok, said = await _arm(rt, texts)
        assert not ok, f"armed without an operator location: {said}"
        failures = [t for t in said if t.startswith(("Arm:", "PreArm:"))]
        if failures and all("OpenDroneID" in t for t in failures):
            return failures
        await asyncio.sleep(1.0)
    raise AssertionError(f"never refused for Remote ID alone: {texts.lines[-10:]}")


@pytest.mark.timeout(240)
async def test_ardupilot_enforcing_remote_id_arms_with_gcs_utm_operator_location(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    parm = tmp_path / "rid.parm"
    parm.write_text(RID_PARAMS)
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(
            links=("tcp:127.0.0.1:5760",), reconnect_min_s=0.2, reconnect_max_s=1.0
        ),
        remote_id=RemoteIdConfig(
            system_period_s=PERIOD_S,
            serial_numbers={"1": SERIAL},
            operator_ids={"default": OPERATOR_ID},
        ),
    )
    lat, lon, ground_m, _ = ARDUPILOT_DEFAULT_HOME
    home = Position(lat_deg=lat, lon_deg=lon, alt_amsl_m=ground_m)
    seen: dict[str, Any] = {}
    tx = Transmitter()
    texts = Texts()

    async def scenario(rt: Runtime) -> None:
        rt.hub.raw_tap = texts.tap
        tx_task: asyncio.Task[None] | None = None
        try:
            ardupilot(instance=0, vehicle="copter", speed=SPEED, defaults=(parm,))
            await until(lambda: bool(rt.hub.vehicles()), 60.0, "vehicle not heard")
            tx_task = asyncio.create_task(tx.run(5762))
            await until(lambda: 1 in rt.hub.remote_id.declared, 30.0, "RID not declared")
            seen["declared_by"] = rt.hub.remote_id.declared[1].how
            seen["refusal"] = await _refused_for_remote_id(rt, texts)
            seen["system_before"] = len(tx.got("OPEN_DRONE_ID_SYSTEM"))
            rt.airspace.add_operation(_operation(home))
            await until(
                lambda: any(m.operator_latitude != 0 for m in tx.got("OPEN_DRONE_ID_SYSTEM")),
                20.0,
                "the operator location did not reach the transmitter",
            )
            # GUIDED, so that the armed copter can take off on command
            await rt.hub.command_long(SysId(1), MAV_CMD_DO_SET_MODE, (1.0, 4.0, 0, 0, 0, 0, 0))
            ok, said = await _arm(rt, texts)
            for _ in range(5):  # a pre-arm check of its own may still be settling
                if ok:
                    break
                await asyncio.sleep(1.0)
                ok, said = await _arm(rt, texts)
            seen["armed"], seen["arm_texts"] = ok, said
            if ok:  # it flies: take off, and the operator location goes on in the air
                await rt.hub.command_long(
                    SysId(1), MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, TAKEOFF_AGL_M)
                )
                await until(lambda: _height_m(rt, home) > 0.8 * TAKEOFF_AGL_M, 60.0, "no climb")
                seen["height_m"] = _height_m(rt, home)
                n_air = len(tx.got("OPEN_DRONE_ID_SYSTEM"))
                await asyncio.sleep(2.0)
                seen["system_in_air"] = len(tx.got("OPEN_DRONE_ID_SYSTEM")) - n_air
                await rt.hub.command_long(SysId(1), MAV_CMD_DO_SET_MODE, (1.0, 9.0, 0, 0, 0, 0, 0))
            seen["counters"] = dataclasses.asdict(rt.remote_id.counters)
        finally:
            if tx_task is not None:
                tx_task.cancel()

    await serve_while(settings, tmp_path / "utm.sqlite", scenario, SPEED)
    # phase 1: refused for the operator location alone
    assert any(ODID_REASON in t for t in seen["refusal"]), seen["refusal"]
    assert seen["system_before"] == 0 or all(
        m.operator_latitude == 0 for m in tx.got("OPEN_DRONE_ID_SYSTEM")[: seen["system_before"]]
    )
    # phase 2: armed with gcs-utm's operator location, which ArduPilot passed on
    assert seen["armed"], seen["arm_texts"]
    assert seen["height_m"] > 0.8 * TAKEOFF_AGL_M and seen["system_in_air"] > 0, seen
    system = [m for m in tx.got("OPEN_DRONE_ID_SYSTEM") if m.operator_latitude != 0][-1]
    assert (system.operator_latitude, system.operator_longitude) == (
        round(lat * 1e7),
        round(lon * 1e7),
    )
    basic = tx.got("OPEN_DRONE_ID_BASIC_ID")
    assert basic and bytes(basic[-1].uas_id).rstrip(b"\0") == SERIAL.encode()
    operator = tx.got("OPEN_DRONE_ID_OPERATOR_ID")
    assert operator and operator[-1].operator_id.rstrip("\x00") == OPERATOR_ID
    assert seen["counters"]["system"] > 0 and seen["counters"]["send_errors"] == 0
