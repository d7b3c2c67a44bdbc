"""A small scripted vehicle for the MAVLink tests: speaks the mission and command protocols
over UDP on 127.0.0.1 with pymavlink directly (not our wire module), with faults on demand."""

from __future__ import annotations

import asyncio
import os
import random
from dataclasses import dataclass, field
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import common as mav

from adapters.mavlink import MavlinkConfig, MavlinkHub
from gcs_utm.clock import RealClock


class Sink:
    def __init__(self) -> None:
        self.measurements: list[Any] = []
        self.statuses: list[Any] = []
        self.hazards: list[Any] = []
        self.vehicles: list[Any] = []
        self.health: list[Any] = []

    def on_measurement(self, m: Any) -> None:
        self.measurements.append(m)

    def on_status(self, s: Any) -> None:
        self.statuses.append(s)

    def on_hazard(self, h: Any) -> None:
        self.hazards.append(h)

    def on_vehicle(self, v: Any) -> None:
        self.vehicles.append(v)

    def on_link_health(self, h: Any) -> None:
        self.health.append(h)


@dataclass
class Faults:
    drop: float = 0.0  # probability of dropping any datagram, each direction
    nack: int | None = None  # MISSION_ACK type to answer the upload with
    silent: bool = False  # never answer
    old_request: bool = False  # ask with MISSION_REQUEST (PX4 v1.15 sometimes does)
    reboot_after_items: int | None = None
    command_result: int = 0
    drop_commands: int = 0  # ignore the first N COMMAND_LONG
    corrupt_readback: bool = False
    refuse_readback: int = 0  # answer the first N readback item requests with MISSION_ACK error
    current_delay_s: float = 0.0  # MISSION_CURRENT this long after MISSION_SET_CURRENT


class FakeVehicle(asyncio.DatagramProtocol):
    """A PX4-like vehicle: sysid, autopilot 12, quadrotor. Re-requests mission items on
    ``rerequest_s`` like PX4 (250 ms there)."""

    def __init__(
        self,
        gcs_port: int,
        sys_id: int = 1,
        *,
        autopilot: int = 12,
        rerequest_s: float = 0.25,
        seed: int = 1,
    ) -> None:
        self.gcs = ("127.0.0.1", gcs_port)
        self.sys_id = sys_id
        self.autopilot = autopilot
        self.rerequest_s = rerequest_s
        self.faults = Faults()
        self.rng = random.Random(seed)
        self.mav = mav.MAVLink(None, srcSystem=sys_id, srcComponent=1)
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.mission: list[Any] = []
        self.current = 0
        self.custom_mode = (4 << 16) | (3 << 24)  # AUTO.LOITER
        self.armed = True  # HEARTBEAT's MAV_MODE_FLAG_SAFETY_ARMED
        self.boot_ms = 60_000
        self.received: list[Any] = []
        self.commands: list[Any] = []
        self._incoming: list[Any | None] = []
        self._count = 0
        self._timer: asyncio.TimerHandle | None = None
        self.transport: asyncio.DatagramTransport | None = None
        self.port = 0

    async def start(self) -> FakeVehicle:
        loop = asyncio.get_running_loop()
        tr, _ = await loop.create_datagram_endpoint(lambda: self, local_addr=("127.0.0.1", 0))
        self.transport = tr
        self.port = tr.get_extra_info("sockname")[1]
        return self

    def close(self) -> None:
        if self._timer:
            self._timer.cancel()
        if self.transport:
            self.transport.close()

    # --- sending ---------------------------------------------------------------------------
    def send(self, msg: Any, *, lossy: bool = True) -> None:
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        if lossy and self.rng.random() < self.faults.drop:
            return
        assert self.transport is not None
        self.transport.sendto(buf, self.gcs)

    def send_raw(self, data: bytes) -> None:
        assert self.transport is not None
        self.transport.sendto(data, self.gcs)

    def heartbeat(self) -> None:
        self.send(
            self.mav.heartbeat_encode(
                2, self.autopilot, 1 | (128 if self.armed else 0), self.custom_mode, 4, 3
            ),
            lossy=False,
        )

    def position(
        self,
        lat: float = 47.3977,
        lon: float = 8.5456,
        alt: float = 488.0,
        boot_ms: int | None = None,
    ) -> None:
        self.boot_ms = self.boot_ms + 100 if boot_ms is None else boot_ms
        self.send(
            self.mav.global_position_int_encode(
                self.boot_ms,
                round(lat * 1e7),
                round(lon * 1e7),
                round(alt * 1000),
                10000,
                100,
                -200,
                50,
                0,
            ),
            lossy=False,
        )

    # --- receiving -------------------------------------------------------------------------
    def datagram_received(self, data: bytes, addr: Any) -> None:
        if self.rng.random() < self.faults.drop:
            return
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "BAD_DATA":
                continue
            self.received.append(m)
            if getattr(m, "target_system", self.sys_id) not in (0, self.sys_id):
                continue
            if not self.faults.silent:
                self.handle(m)

    def _request(self) -> None:
        if self._timer:
            self._timer.cancel()
        seq = len(self._incoming)
        if self.faults.old_request:
            self.send(self.mav.mission_request_encode(255, 190, seq, 0))
        else:
            self.send(self.mav.mission_request_int_encode(255, 190, seq, 0))
        self._timer = asyncio.get_running_loop().call_later(self.rerequest_s, self._request)

    def handle(self, m: Any) -> None:
        t = m.get_type()
        if t == "MISSION_COUNT":
            self._count = m.count
            self._incoming = []
            self._request()
        elif t == "MISSION_ITEM_INT" and self._timer is not None:
            if m.seq != len(self._incoming):
                return
            self._incoming.append(m)
            if self.faults.reboot_after_items == len(self._incoming):
                self._timer.cancel()
                self._timer = None
                self.boot_ms = 500
                self.mav.seq = 0
                self.position(boot_ms=500)
                return
            if len(self._incoming) < self._count:
                self._request()
                return
            self._timer.cancel()
            self._timer = None
            if self.faults.nack is not None:
                self.send(self.mav.mission_ack_encode(255, 190, self.faults.nack, 0))
                return
            self.mission = list(self._incoming)
            for it in self.mission:
                if it.current:
                    self.current = it.seq
            self.send(self.mav.mission_ack_encode(255, 190, 0, 0))
        elif t == "MISSION_REQUEST_LIST":
            self.send(self.mav.mission_count_encode(255, 190, len(self.mission), 0))
        elif t in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            if self.faults.refuse_readback > 0:  # as PX4 does when it dropped the transfer
                self.faults.refuse_readback -= 1
                self.send(self.mav.mission_ack_encode(255, 190, 1, 0))  # MAV_MISSION_ERROR
                return
            if m.seq < len(self.mission):
                it = self.mission[m.seq]
                z = it.z + (5.0 if self.faults.corrupt_readback else 0.0)
                self.send(
                    self.mav.mission_item_int_encode(
                        255,
                        190,
                        it.seq,
                        it.frame,
                        it.command,
                        int(it.seq == self.current),
                        it.autocontinue,
                        it.param1,
                        it.param2,
                        it.param3,
                        it.param4,
                        it.x,
                        it.y,
                        z,
                        0,
                    )
                )
        elif t == "MISSION_SET_CURRENT":
            if m.seq < len(self.mission):
                self.current = m.seq
            answer = self.mav.mission_current_encode(self.current, len(self.mission))
            if self.faults.current_delay_s > 0.0:
                loop = asyncio.get_running_loop()
                loop.call_later(self.faults.current_delay_s, self.send, answer)
            else:
                self.send(answer)
        elif t in ("COMMAND_LONG", "COMMAND_INT"):
            self.commands.append(m)
            if t == "COMMAND_LONG" and m.command == 511:
                return
            if self.faults.drop_commands > 0:
                self.faults.drop_commands -= 1
                return
            if m.command == 176 and self.faults.command_result == 0:
                self.custom_mode = (int(m.param2) << 16) | (int(m.param3) << 24)
                self.heartbeat()  # (a real vehicle's next 1 Hz heartbeat shows the mode)
            self.send(self.mav.command_ack_encode(m.command, self.faults.command_result))


@dataclass
class Env:
    hub: MavlinkHub
    sink: Sink
    port: int
    link: str
    taps: list[tuple[str, bytes, float]] = field(default_factory=list)

    async def vehicle(self, sys_id: int = 1, **kw: Any) -> FakeVehicle:
        v = await FakeVehicle(self.port, sys_id, **kw).start()
        v.heartbeat()
        for _ in range(200):
            await asyncio.sleep(0.005)
            if any(
                x.key.sys_id == sys_id and x.key.address.endswith(f":{v.port}")
                for x in self.sink.vehicles
            ):
                return v
        raise AssertionError("hub did not discover the vehicle")


@pytest.fixture
async def env() -> Any:
    cfg = MavlinkConfig(
        links=("udpin:127.0.0.1:0",),
        command_timeout_s=0.1,
        heartbeat_period_s=0.2,
        health_period_s=0.1,
    )
    sink = Sink()
    taps: list[tuple[str, bytes, float]] = []
    hub = MavlinkHub(cfg, RealClock(), sink, raw_tap=lambda *a: taps.append(a))
    await hub.start()
    link = next(iter(hub._links))
    e = Env(hub=hub, sink=sink, port=hub.local_port(link), link=link, taps=taps)
    yield e
    await hub.close()


@pytest.fixture
def fake_vehicle_cls() -> type[FakeVehicle]:
    return FakeVehicle
