"""asyncio transports for MAVLink links: UDP (in/out), TCP client and serial (termios, no
pyserial). Each delivers ``(bytes, address)`` chunks to a callback and offers ``send``.
Nothing here blocks the loop; OS errors are translated to :class:`LinkError` ``from exc``."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import termios
import tty
from collections.abc import Callable

from adapters.mavlink.endpoint import Endpoint, EndpointKind

_log = logging.getLogger(__name__)

Address = tuple[str, int]
OnChunk = Callable[[bytes, Address | None], None]

_MAX_DATAGRAM = 65535  # never truncate: PX4 packs several frames into one datagram


class LinkError(OSError):
    """A link that cannot be opened or written; ``endpoint`` says which."""

    def __init__(self, endpoint: str, message: str) -> None:
        super().__init__(f"{endpoint}: {message}")
        self.endpoint = endpoint
        self.message = message


def set_rcvbuf(sock: socket.socket, want: int, what: str) -> int:
    """Ask for a ``want``-byte receive buffer and return what the kernel granted
    (getsockopt; Linux reports twice the usable size it books). SO_RCVBUF is capped at
    net.core.rmem_max; as root (CAP_NET_ADMIN) SO_RCVBUFFORCE lifts the cap. A smaller
    buffer than asked is logged once with the sysctl that fixes it."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, want)
    got = int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    force = getattr(socket, "SO_RCVBUFFORCE", None)
    if got < want and force is not None:
        with contextlib.suppress(OSError):  # EPERM without CAP_NET_ADMIN
            sock.setsockopt(socket.SOL_SOCKET, force, want)
            got = int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    if got < want:
        _log.warning(
            "%s: UDP receive buffer is %d bytes, asked for %d (capped by net.core.rmem_max: "
            "`sysctl -w net.core.rmem_max=%d`, or run with CAP_NET_ADMIN); bursts may drop",
            what,
            got,
            want,
            want,
        )
    return got


class _Stream(asyncio.Protocol):
    def __init__(self, on_chunk: OnChunk, peer: Address) -> None:
        self.on_chunk = on_chunk
        self.peer = peer
        self.closed = asyncio.get_running_loop().create_future()

    def data_received(self, data: bytes) -> None:
        self.on_chunk(data, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.closed.done():
            self.closed.set_result(None)


class Transport:
    """One open link. ``datagram`` links parse each chunk on its own."""

    def __init__(self, endpoint: Endpoint) -> None:
        self.endpoint = endpoint
        self.datagram = endpoint.kind in (EndpointKind.UDPIN, EndpointKind.UDPOUT)
        self.local_port = 0
        self.default_peer: Address | None = None
        self.errors = [0]
        self._sock: socket.socket | None = None
        self.rcvbuf_bytes = 0  # effective UDP receive buffer (getsockopt), 0 for other links
        self._tcp: asyncio.Transport | None = None
        self._fd = -1

    async def open(
        self,
        on_chunk: OnChunk,
        rcvbuf: int,
        batch: int = 64,
        on_burst: Callable[[], None] | None = None,
    ) -> None:
        """Start delivering chunks to ``on_chunk``; a UDP link reads up to ``batch``
        datagrams per wake-up and then calls ``on_burst`` (when given)."""
        ep = self.endpoint
        loop = asyncio.get_running_loop()
        try:
            if self.datagram:
                sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                try:
                    self.rcvbuf_bytes = set_rcvbuf(sock, rcvbuf, str(ep))
                    sock.setblocking(False)
                    if ep.kind is EndpointKind.UDPIN:
                        sock.bind((ep.host, ep.port))
                    else:
                        sock.bind(("0.0.0.0", 0))
                        self.default_peer = (socket.gethostbyname(ep.host), ep.port)
                except OSError:
                    sock.close()
                    raise
                self.local_port = int(sock.getsockname()[1])
                self._sock = sock
                loop.add_reader(
                    sock.fileno(), self._read_udp, sock, on_chunk, max(1, batch), on_burst
                )
            elif ep.kind is EndpointKind.TCP:
                peer = (ep.host, ep.port)
                tr2, _ = await loop.create_connection(
                    lambda: _Stream(on_chunk, peer), ep.host, ep.port
                )
                self._tcp = tr2
                self.default_peer = peer
                self.local_port = int(tr2.get_extra_info("sockname")[1])
            else:
                self._open_serial(on_chunk)
        except OSError as exc:
            raise LinkError(str(ep), f"cannot open: {exc}") from exc

    def _read_udp(
        self,
        sock: socket.socket,
        on_chunk: OnChunk,
        batch: int,
        on_burst: Callable[[], None] | None,
    ) -> None:
        recvfrom = sock.recvfrom
        try:
            for _ in range(batch):
                try:
                    data, addr = recvfrom(_MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    return
                except OSError as exc:
                    # ICMP port unreachable after sending to a vehicle that went away: count,
                    # go on
                    self.errors[0] += 1
                    _log.debug("udp receive on %s: %s", self.endpoint, exc)
                    return
                on_chunk(data, addr)  # (host, port) for AF_INET
        finally:
            if on_burst is not None:
                on_burst()

    def _open_serial(self, on_chunk: OnChunk) -> None:
        ep = self.endpoint
        fd = os.open(ep.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            tty.setraw(fd)
            attrs = termios.tcgetattr(fd)
            speed = getattr(termios, f"B{ep.baud}")
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
        except (termios.error, AttributeError) as exc:
            os.close(fd)
            raise OSError(f"cannot configure {ep.device} at {ep.baud}: {exc}") from exc
        self._fd = fd
        peer = (ep.device, ep.baud)
        self.default_peer = peer

        def readable() -> None:
            try:
                data = os.read(fd, 65536)
            except BlockingIOError:
                return
            except OSError as exc:
                _log.warning("serial %s read failed: %s", ep.device, exc)
                asyncio.get_running_loop().remove_reader(fd)
                return
            if data:
                on_chunk(data, peer)

        asyncio.get_running_loop().add_reader(fd, readable)

    def send(self, data: bytes, addr: Address | None) -> None:
        """Send one frame; to ``addr`` on UDP (or the udpout peer). Never raises: a failed
        send is counted (the protocol layers retry)."""
        try:
            if self._sock is not None:
                dest = addr or self.default_peer
                if dest is not None:
                    self._sock.sendto(data, dest)
            elif self._tcp is not None:
                self._tcp.write(data)
            elif self._fd >= 0:
                os.write(self._fd, data)
        except OSError as exc:
            self.errors[0] += 1
            _log.debug("send on %s failed: %s", self.endpoint, exc)

    def close(self) -> None:
        if self._sock is not None:
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                asyncio.get_running_loop().remove_reader(self._sock.fileno())
            self._sock.close()
            self._sock = None
        if self._tcp is not None:
            self._tcp.close()
        if self._fd >= 0:
            with contextlib.suppress(RuntimeError):
                asyncio.get_running_loop().remove_reader(self._fd)
            os.close(self._fd)
            self._fd = -1
