"""A second sender claiming the system id of a flying vehicle (two vehicles left on sysid 1, a
stray sender) is a SYSID_CONFLICT: the operator is warned, the threat is stored and the warning
audited; the real vehicle is neither held nor landed, even in autonomous mode. GNSS spoofing
the vehicle reports itself stays a SPOOFING_ATTACK (suspend_and_geofence)."""

from __future__ import annotations

import asyncio
import dataclasses
import os
import time
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink.config import MavlinkConfig
from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.core.emergency import EmergencyConfig
from gcs_utm.model import (
    FlightPlan,
    Operation,
    OperationId,
    SysId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.settings import Settings
from gcs_utm.store import Store

OP = OperationId("UAS1")
LAT0, LON0, ALT_AMSL_M = 45.467116, -73.757837, 82.34  # 50 m above the default ground
SPEED_MPS = 5.0
M_PER_DEG_LAT = 111_132.0
_SUSPEND_COMMANDS = frozenset({176, 21, 20})  # DO_SET_MODE (hold), NAV_LAND, NAV_RTL


def _at(t_s: float, t0_s: float) -> tuple[float, float]:
    """The plan's position at ``t_s``: north from the origin at SPEED_MPS."""
    return LAT0 + SPEED_MPS * (t_s - t0_s) / M_PER_DEG_LAT, LON0


def _operation(t0_s: float) -> Operation:
    wps = []
    for dt in (0.0, 300.0):
        lat, lon = _at(t0_s + dt, t0_s)
        wps.append(Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=ALT_AMSL_M, t_s=t0_s + dt))
    return Operation(
        id=OP,
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=FlightPlan(operation_id=OP, version=1, waypoints=tuple(wps)),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=SPEED_MPS,
        flight_geometry_m=10.0,
        operational_volume_m=30.0,
    )


class _Sender(asyncio.DatagramProtocol):
    """A PX4 quadrotor on sysid 1 flying the plan, written with pymavlink; keeps what the
    ground sends it."""

    def __init__(self, t0_s: float) -> None:
        self.t0_s = t0_s
        self.enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.received: list[Any] = []
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        self.received.extend(self.parser.parse_buffer(data) or [])

    def send_state(self, port: int) -> None:
        assert self.transport is not None
        now = time.time()
        lat, lon = _at(now, self.t0_s)
        boot_ms = int((now - self.t0_s) * 1000) + 10_000
        hb = self.enc.heartbeat_encode(2, 12, 129 | 128, 4 << 16 | 4 << 24, 4)
        vn = round(SPEED_MPS * 100)
        gp = self.enc.global_position_int_encode(
            boot_ms,
            round(lat * 1e7),
            round(lon * 1e7),
            round(ALT_AMSL_M * 1e3),
            50_000,
            vn,
            0,
            0,
            0,
        )
        for msg in (hb, gp):
            self.transport.sendto(bytes(msg.pack(self.enc)), ("127.0.0.1", port))

    def suspend_commands(self) -> list[Any]:
        return [
            m
            for m in self.received
            if m.get_type() == "COMMAND_LONG" and int(m.command) in _SUSPEND_COMMANDS
        ]


async def _until(cond: Any, timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, what
        await asyncio.sleep(0.05)


async def test_a_sysid_claim_warns_and_the_vehicle_flies_on(tmp_path: Path) -> None:
    t0_s = time.time() - 5.0
    db = tmp_path / "utm.sqlite"
    store = Store(db)
    op = _operation(t0_s)
    store.save_operation(op)
    store.save_plan(op.plan)
    store.close()
    # autonomous: a decision to suspend would be commanded at once, not only proposed
    settings = dataclasses.replace(
        Settings(),
        mavlink=MavlinkConfig(links=("udpin:127.0.0.1:0",)),
        emergency=EmergencyConfig(autonomous=True),
    )
    stop = asyncio.Event()
    seen: dict[str, Any] = {}

    async def drive(rt: Runtime) -> None:
        """Runs beside the service's tasks: the vehicle, the impostor, then stop."""
        loop = asyncio.get_running_loop()
        port = rt.hub.local_port(rt.hub.link_names()[0])
        _, owner = await loop.create_datagram_endpoint(
            lambda: _Sender(t0_s), local_addr=("127.0.0.1", 0)
        )
        _, impostor = await loop.create_datagram_endpoint(
            lambda: _Sender(t0_s), local_addr=("127.0.0.1", 0)
        )
        seen["owner"] = owner

        async def fly() -> None:
            while not stop.is_set():
                owner.send_state(port)
                if rt.hub.counters.frames > 20:  # the owner is bound: now the claim
                    impostor.send_state(port)
                await asyncio.sleep(0.1)

        task = asyncio.create_task(fly())

        def claimed() -> bool:
            return any(t.kind is ThreatKind.SYSID_CONFLICT for t in rt.usm.threat_log)

        def warned() -> bool:
            return any(e.kind == "warning" and "SYSID_CONFLICT" in e.text for e in rt.usm.events)

        try:
            await _until(claimed, 15.0, "no SYSID_CONFLICT threat")
            await _until(warned, 10.0, "no operator warning for the claim")
            await asyncio.sleep(1.5)  # time for any command to reach the vehicle
            seen["threats"] = list(rt.usm.threat_log)
            seen["claims"] = rt.hub.counters.sysid_claims
            seen["bound"] = rt.hub.state(SysId(1)).key.address
            seen["owner_addr"] = owner.transport.get_extra_info("sockname")
        finally:
            stop.set()
            await task
            owner.transport.close()
            impostor.transport.close()

    drivers: list[asyncio.Task[None]] = []

    async def on_runtime(rt: Runtime) -> None:
        drivers.append(asyncio.create_task(drive(rt)))

    code = await serve(
        settings,
        db_path=db,
        operator=OperatorMode.NONE,
        headless=False,
        stop=stop,
        on_runtime=on_runtime,
    )
    assert code == 0
    await drivers[0]  # its assertions
    # the real vehicle stays bound and is never told to hold, land or return
    host, port = seen["owner_addr"]
    assert seen["bound"] == f"{host}:{port}" and seen["claims"] > 0
    assert seen["owner"].suspend_commands() == []
    kinds = {t.kind for t in seen["threats"]}
    assert ThreatKind.SYSID_CONFLICT in kinds and ThreatKind.SPOOFING_ATTACK not in kinds
    claim = next(t for t in seen["threats"] if t.kind is ThreatKind.SYSID_CONFLICT)
    assert claim.uas_ids == (OP,) and "claimed by another sender" in claim.message
    # stored, audited as a warning; no recommendation, no geofence for it
    store = Store(db)
    try:
        stored = [t for t in store.load_threats() if t.id == claim.id]
        assert [t.kind for t in stored] == [ThreatKind.SYSID_CONFLICT]
        warns = [a for a in store.load_audit() if a.action == "warn" and a.subject == claim.id]
        assert len(warns) == 1 and "SYSID_CONFLICT" in str(warns[0].detail["message"])
        recs = store.load_recommendations()
        assert [r for r in recs if r.threat_id == claim.id] == []
        assert not [r for r in recs if r.command is not None]
        assert store.load_geofences() == []
    finally:
        store.close()
