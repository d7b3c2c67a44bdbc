"""The links of one simulated vehicle and their receive path: sockets bound at start (PX4: UDP
GCS and API links; ArduPilot: a TCP server, UDP only when given a port), link faults applied
both ways (link loss, packet loss, latency), incoming bytes parsed and counted, and each
message handed to the vehicle's ``deliver`` callback.

Nothing here blocks and nothing a peer sends can raise out of the receive path: bad input is
counted in ``counters`` (and rejected signatures per message in ``rejected_messages``)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
from collections.abc import Callable

from sitl._mav import Inbound, name_of
from sitl.core import Timeline
from sitl.faults import Faults
from sitl.links import Link, StreamState, TcpLink, UdpLink
from sitl.spec import ARDUPILOT, VehicleSpec

_log = logging.getLogger(__name__)


class Transport:
    """The :class:`sitl.links.LinkHost` of a vehicle's links (see the module docstring)."""

    def __init__(
        self,
        *,
        spec: VehicleSpec,
        time: Timeline,
        faults: Faults,
        rng: random.Random,
        counters: dict[str, int],
        deliver: Callable[[Link, Inbound], None],
    ) -> None:
        self._spec = spec
        self._time = time
        self._faults = faults
        self._rng = rng
        self._deliver = deliver
        self.sys_id = spec.system_id
        self.signing_key = spec.signing_key_bytes()
        self.counters = counters
        # signing on: message name -> count of incoming messages dropped for their signature
        self.rejected_messages: dict[str, int] = {}
        self.links: list[Link] = []
        self._udp: UdpLink | None = None
        self._api: UdpLink | None = None
        self._tcp_server: asyncio.Server | None = None
        self._boot_rates_hz: dict[str, float] = {}  # the streams of a link at boot

    @property
    def local_port(self) -> int:
        return self._udp.local_port if self._udp is not None else 0

    @property
    def api_local_port(self) -> int:
        return self._api.local_port if self._api is not None else 0

    @property
    def tcp_port(self) -> int:
        if self._tcp_server is None or not self._tcp_server.sockets:
            return 0
        return int(self._tcp_server.sockets[0].getsockname()[1])

    def broadcast(self, name: str, **fields: object) -> None:
        for link in list(self.links):
            link.send(name, **fields)

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        spec = self._spec
        ardupilot = spec.autopilot == ARDUPILOT
        streaming = dict(spec.stream_rates_hz)
        if ardupilot:
            # ArduPilot streams nothing but HEARTBEAT until asked (SRx_ params at 0).
            streaming = {"HEARTBEAT": streaming.get("HEARTBEAT", 1.0)}
        self._boot_rates_hz = streaming
        want_udp = not ardupilot or spec.bind_port is not None
        if want_udp:
            port = spec.bind_port if spec.bind_port is not None else 18570 + spec.instance
            link = UdpLink(self, "gcs", streaming, (spec.gcs_host, spec.gcs_port))
            await loop.create_datagram_endpoint(lambda: link, local_addr=(spec.bind_host, port))
            self._udp = link
            self.links.append(link)
        if spec.api_link:
            port = spec.api_bind_port if spec.api_bind_port is not None else 18580 + spec.instance
            # PX4's API link binds 14580+i: keep the convention unless a port is given.
            if spec.api_bind_port is None:
                port = 14580 + spec.instance
            remote = (
                spec.gcs_host,
                spec.api_port if spec.api_port is not None else 14540 + spec.instance,
            )
            api = UdpLink(self, "api", streaming, remote, link_id=1)
            await loop.create_datagram_endpoint(lambda: api, local_addr=(spec.bind_host, port))
            self._api = api
            self.links.append(api)
        if ardupilot:
            tport = spec.tcp_port if spec.tcp_port is not None else 5760 + 10 * spec.instance
            self._tcp_server = await loop.create_server(
                lambda: TcpLink(self, {"HEARTBEAT": 1.0}), host=spec.bind_host, port=tport
            )

    async def stop(self) -> None:
        for link in list(self.links):
            link.closed = True
            tr = getattr(link, "transport", None)
            if tr is not None:
                tr.close()
        self.links.clear()
        if self._tcp_server is not None:
            self._tcp_server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._tcp_server.wait_closed(), 1.0)

    def reboot(self) -> None:
        """The autopilot restarts: its TCP connections drop (ArduPilot SITL's server goes
        with the process; the ground station connects again) and every UDP link is back to
        the streams it has at boot (ArduPilot: HEARTBEAT only until asked again)."""
        for link in list(self.links):
            if isinstance(link, TcpLink):
                if link.transport is not None:
                    link.transport.close()
                continue
            link.streams = {
                n: StreamState(1.0 / hz if hz > 0 else 0.0) for n, hz in self._boot_rates_hz.items()
            }

    def out(self, link: Link, data: bytes) -> None:
        if not self._time.booted:
            return
        faults = self._faults
        if faults.link_loss:
            self.counters["dropped_link_loss"] += 1
            return
        if faults.packet_loss > 0 and self._rng.random() < faults.packet_loss:
            self.counters["dropped_packet_loss"] += 1
            return
        self.counters["tx_messages"] += 1
        if faults.latency_s > 0:
            self.counters["delayed_latency"] += 1
            asyncio.get_running_loop().call_later(
                self._time.real_delay_s(faults.latency_s), link.transmit, data
            )
        else:
            link.transmit(data)

    def inbound(self, link: Link, data: bytes, peer: tuple[str, int] | None) -> None:
        if not self._time.booted:
            return
        self.counters["rx_datagrams"] += 1
        faults = self._faults
        if faults.link_loss:
            self.counters["dropped_link_loss"] += 1
            return
        if faults.packet_loss > 0 and self._rng.random() < faults.packet_loss:
            self.counters["dropped_packet_loss"] += 1
            return
        if faults.latency_s > 0:
            self.counters["delayed_latency"] += 1
            asyncio.get_running_loop().call_later(
                self._time.real_delay_s(faults.latency_s), self._receive, link, data, peer
            )
        else:
            self._receive(link, data, peer)

    def _receive(self, link: Link, data: bytes, peer: tuple[str, int] | None) -> None:
        try:
            if isinstance(link, UdpLink) and peer is not None:
                res = link.parser_for(peer).parse_datagram(data)
            elif isinstance(link, TcpLink):
                res = link.parser.parse_stream(data)
            else:
                return
            c = self.counters
            c["garbage"] += res.garbage
            c["bad_crc"] += res.bad_crc
            c["bad_frame"] += res.bad_frame
            c["truncated"] += res.truncated
            c["unknown_msgid"] += res.unknown_msgid
            if res.rejected_msg_ids:
                c["rejected_unsigned"] += res.unsigned_rejected
                c["rejected_bad_signature"] += res.bad_signature
                for mid in res.rejected_msg_ids:
                    name = name_of(mid) or f"MSG_{mid}"
                    self.rejected_messages[name] = self.rejected_messages.get(name, 0) + 1
            if (
                res.messages
                and isinstance(link, UdpLink)
                and peer is not None
                and not link.remote_learned
            ):
                # As PX4: the first peer that talks to us becomes the reply address.
                link.remote = peer
                link.remote_learned = True
            for m in res.messages:
                c["rx_messages"] += 1
                try:
                    self._deliver(link, m)
                except Exception:
                    c["handler_errors"] += 1
                    _log.exception("sysid %d: error handling %s", self.sys_id, m.type)
        except Exception:
            self.counters["handler_errors"] += 1
            _log.exception("sysid %d: error receiving", self.sys_id)
