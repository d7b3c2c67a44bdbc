"""MAVLink channels of a simulated vehicle: UDP (PX4's GCS and API links) and TCP (ArduPilot's
SERIAL0), each with its own sequence numbers, signing link id and set of streams.

A link hands what it encodes and what it receives to its :class:`LinkHost` (the vehicle's
:class:`sitl.transport.Transport`), which applies the link faults and parses."""

from __future__ import annotations

import asyncio
import contextlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Protocol, cast

from sitl._mav import Encoder, Inbound, Parser

MAX_PEERS = 32  # parser states kept per UDP link (one per source address)


@dataclass(slots=True)
class StreamState:
    period_s: float  # simulated seconds; <= 0: off
    next_due_s: float = 0.0
    last_real_s: float = 0.0


class LinkHost(Protocol):
    """What a link needs of the vehicle's side: identity, counters, the list of live links,
    and where its outgoing frames and incoming bytes go."""

    sys_id: int
    signing_key: bytes | None
    counters: dict[str, int]
    links: list[Link]

    def out(self, link: Link, data: bytes) -> None:
        """Send one encoded frame on ``link`` (link faults applied)."""
        ...

    def inbound(self, link: Link, data: bytes, peer: tuple[str, int] | None) -> None:
        """Bytes received on ``link`` from ``peer`` (None: a stream link)."""
        ...


class Link(ABC):
    """A MAVLink channel of the vehicle with its own sequence numbers and stream set."""

    name: str

    def __init__(
        self, host: LinkHost, name: str, rates_hz: dict[str, float], link_id: int = 0
    ) -> None:
        self.host = host
        self.name = name
        # signing: one signing link id per channel, as PX4 (its MAVLink instance number)
        self.encoder = Encoder(host.sys_id, 1, key=host.signing_key, link_id=link_id)
        self.streams: dict[str, StreamState] = {
            n: StreamState(1.0 / hz if hz > 0 else 0.0) for n, hz in rates_hz.items()
        }
        self.closed = False

    def set_rate(self, stream: str, hz: float) -> None:
        st = self.streams.setdefault(stream, StreamState(0.0))
        st.period_s = 1.0 / hz if hz > 0 else 0.0
        st.next_due_s = 0.0

    def send(self, name: str, **fields: Any) -> None:
        if self.closed:
            return
        data = self.encoder.pack(name, **fields)
        self.host.out(self, data)

    @abstractmethod
    def transmit(self, data: bytes) -> None:
        """Put one encoded frame on the wire."""


class UdpLink(Link, asyncio.DatagramProtocol):
    def __init__(
        self,
        host: LinkHost,
        name: str,
        rates_hz: dict[str, float],
        remote: tuple[str, int],
        link_id: int = 0,
    ) -> None:
        Link.__init__(self, host, name, rates_hz, link_id)
        self.remote = remote
        self.remote_learned = False
        self.transport: asyncio.DatagramTransport | None = None
        self.parsers: dict[tuple[str, int], Parser] = {}

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Python 3.11's selector datagram transport does not subclass DatagramTransport.
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        peer = (str(addr[0]), int(addr[1]))
        self.host.inbound(self, data, peer)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when nobody listens on the GCS port: normal before a GCS starts.
        self.host.counters["link_errors"] = self.host.counters.get("link_errors", 0) + 1

    def parser_for(self, peer: tuple[str, int]) -> Parser:
        p = self.parsers.get(peer)
        if p is None:
            if len(self.parsers) >= MAX_PEERS:
                self.parsers.pop(next(iter(self.parsers)))
            p = self.parsers[peer] = Parser(self.host.signing_key)
        return p

    def transmit(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.sendto(data, self.remote)

    @property
    def local_port(self) -> int:
        if self.transport is None:
            return 0
        return int(self.transport.get_extra_info("sockname")[1])


class TcpLink(Link, asyncio.Protocol):
    def __init__(self, host: LinkHost, rates_hz: dict[str, float]) -> None:
        Link.__init__(self, host, "tcp", rates_hz, link_id=2)
        self.transport: asyncio.Transport | None = None
        self.parser = Parser(host.signing_key)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.host.links.append(self)

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed = True
        with contextlib.suppress(ValueError):
            self.host.links.remove(self)

    def data_received(self, data: bytes) -> None:
        self.host.inbound(self, data, None)

    def transmit(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)


def send_ack(link: Link, m: Inbound, command: int, result: int) -> None:
    """COMMAND_ACK of ``command`` to the sender of ``m``."""
    link.send(
        "COMMAND_ACK",
        command=command,
        result=result,
        progress=0,
        result_param2=0,
        target_system=m.src_system,
        target_component=m.src_component,
    )
