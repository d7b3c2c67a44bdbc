"""Raw pymavlink ground station for sitl tests, written here and not shared with sitl."""

from __future__ import annotations

import asyncio
import contextlib
import os
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mav

import sitl


class RawGcs(asyncio.DatagramProtocol):
    """A ground station on 127.0.0.1:<ephemeral>, keeping every decoded message."""

    def __init__(self) -> None:
        self.enc = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self.dec = mav.MAVLink(None)
        self.dec.robust_parsing = True
        self.msgs: list[Any] = []
        self.senders: set[tuple[str, int]] = set()
        self.transport: asyncio.DatagramTransport | None = None
        self.new = asyncio.Event()
        self.last_index = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.senders.add((addr[0], addr[1]))
        for m in self.dec.parse_buffer(data) or []:
            self.msgs.append(m)
        self.new.set()

    @property
    def port(self) -> int:
        assert self.transport is not None
        return int(self.transport.get_extra_info("sockname")[1])

    def send(self, port: int, msg: Any) -> None:
        assert self.transport is not None
        self.transport.sendto(msg.pack(self.enc), ("127.0.0.1", port))

    def raw(self, port: int, data: bytes) -> None:
        assert self.transport is not None
        self.transport.sendto(data, ("127.0.0.1", port))

    async def wait(self, pred: Callable[[Any], bool], timeout: float = 3.0, start: int = 0) -> Any:
        deadline = time.monotonic() + timeout
        idx = start
        while True:
            while idx < len(self.msgs):
                m = self.msgs[idx]
                idx += 1
                if pred(m):
                    self.last_index = idx  # position after the match (pymavlink __eq__ is by value)
                    return m
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no matching message")
            self.new.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.new.wait(), left)

    async def wait_type(
        self, kind: str, timeout: float = 3.0, start: int | None = None, **eq: Any
    ) -> Any:
        return await self.wait(
            lambda m: m.get_type() == kind and all(getattr(m, k) == v for k, v in eq.items()),
            timeout,
            len(self.msgs) if start is None else start,
        )


@pytest.fixture
async def gcs() -> AsyncIterator[RawGcs]:
    loop = asyncio.get_running_loop()
    proto = RawGcs()
    await loop.create_datagram_endpoint(lambda: proto, local_addr=("127.0.0.1", 0))
    yield proto
    assert proto.transport is not None
    proto.transport.close()


def px4_spec(gcs_port: int, **kw: Any) -> sitl.VehicleSpec:
    kw.setdefault("instance", 0)
    return sitl.VehicleSpec(gcs_port=gcs_port, bind_port=0, **kw)


WP = [
    sitl.MissionItemSpec(lat_deg=47.3982, lon_deg=8.5456, alt_amsl_m=500.0),
    sitl.MissionItemSpec(lat_deg=47.3982, lon_deg=8.5466, alt_amsl_m=500.0, speed_mps=6.0),
    sitl.MissionItemSpec(lat_deg=47.3977, lon_deg=8.5466, alt_amsl_m=505.0),
]
