"""asyncio transports for MAVLink links: UDP (in/out), TCP client and serial (termios, no
pyserial). Each delivers ``(bytes, address)`` chunks to a callback and offers ``send``.
Nothing here blocks the loop; OS errors are translated to :class:`LinkError` ``from exc``.

Stream links (TCP, serial) survive their peer: given a :class:`Backoff`, a link that cannot be
opened, or that closes (the autopilot restarted, the cable was pulled), is retried after
``min_s``, then twice as long each time up to ``max_s``, until it is up again or closed;
``on_state(up)`` reports each change. While it is down, :meth:`Transport.send` drops the frame
and counts it (``dropped_down``) instead of writing to a dead socket (asyncio logs a warning
for every write to a closed transport). One log line per failed attempt would flood a log
during a long outage: the first failure and every change are logged, the retries in between
at most once per 30 s (a :class:`~gcs_utm.ratelog.RateLimitedLog`, with the count).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import termios
import tty
from collections.abc import Callable
from dataclasses import dataclass

from adapters.mavlink.endpoint import Endpoint, EndpointKind
from gcs_utm.ratelog import RateLimitedLog

_log = logging.getLogger(__name__)

Address = tuple[str, int]
OnChunk = Callable[[bytes, Address | None], None]
OnState = Callable[[bool], None]

_MAX_DATAGRAM = 65535  # never truncate: PX4 packs several frames into one datagram
# A TCP connect to a host that does not answer (no RST) would wait for the kernel's SYN
# retries (minutes) and hold `serve`'s start: give up sooner and let the backoff retry.
_CONNECT_TIMEOUT_S = 5.0


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


@dataclass(frozen=True, slots=True, kw_only=True)
class Backoff:
    """Reconnect delays of a stream link: ``min_s``, doubled per failed attempt, at most
    ``max_s``."""

    min_s: float = 0.5
    max_s: float = 10.0

    def __post_init__(self) -> None:
        if not 0.0 < self.min_s <= self.max_s:
            raise ValueError(
                f"reconnect backoff needs 0 < min_s <= max_s, got {self.min_s} and {self.max_s}"
            )

    def delay_s(self, failures: int) -> float:
        """The wait before the next attempt after ``failures`` failed ones (>= 1)."""
        return min(self.max_s, self.min_s * 2.0 ** min(max(failures - 1, 0), 60))


class _Stream(asyncio.Protocol):
    def __init__(self, on_chunk: OnChunk, peer: Address) -> None:
        self.on_chunk = on_chunk
        self.peer = peer
        self.closed: asyncio.Future[Exception | None] = asyncio.get_running_loop().create_future()

    def data_received(self, data: bytes) -> None:
        self.on_chunk(data, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.closed.done():
            self.closed.set_result(exc)


class Transport:
    """One link. ``datagram`` links parse each chunk on its own. A stream link opened with a
    :class:`Backoff` reconnects (module docstring); ``up`` tells whether it is open now."""

    def __init__(self, endpoint: Endpoint, backoff: Backoff | None = None) -> None:
        self.endpoint = endpoint
        self.datagram = endpoint.kind in (EndpointKind.UDPIN, EndpointKind.UDPOUT)
        self.backoff = None if self.datagram else backoff
        self.local_port = 0
        self.default_peer: Address | None = None
        self.errors = [0]
        self.up = False
        self.connects = 0  # successful opens of a stream link (reconnects = connects - 1)
        self.failures = 0  # failed opens in a row (reset by a successful one)
        self.dropped_down = 0  # frames not sent because the link was down
        self.last_error = ""
        self._sock: socket.socket | None = None
        self.rcvbuf_bytes = 0  # effective UDP receive buffer (getsockopt), 0 for other links
        self._tcp: asyncio.Transport | None = None
        self._stream: _Stream | None = None
        self._fd = -1
        self._serial_closed: asyncio.Future[None] | None = None
        self._on_chunk: OnChunk | None = None
        self._on_state: OnState | None = None
        self._keeper: asyncio.Task[None] | None = None
        self._closing = False
        # retries of a long outage: one line per 30 s at most (or per 3 attempts, if slower)
        self._ratelog = RateLimitedLog(_log, max(30.0, 3.0 * backoff.max_s) if backoff else 30.0)

    async def open(
        self,
        on_chunk: OnChunk,
        rcvbuf: int,
        batch: int = 64,
        on_burst: Callable[[], None] | None = None,
        on_state: OnState | None = None,
    ) -> None:
        """Start delivering chunks to ``on_chunk``; a UDP link reads up to ``batch``
        datagrams per wake-up and then calls ``on_burst`` (when given). A stream link with a
        backoff does not raise when its peer is not there yet: it logs and keeps trying in
        the background, calling ``on_state(True)`` once open (and ``on_state(False)`` when it
        closes again)."""
        ep = self.endpoint
        self._on_chunk = on_chunk
        self._on_state = on_state
        if self.datagram:
            try:
                self._open_udp(on_chunk, rcvbuf, batch, on_burst)
            except OSError as exc:
                raise LinkError(str(ep), f"cannot open: {exc}") from exc
            self.up = True
            return
        try:
            await self._open_stream()
        except OSError as exc:
            if self.backoff is None:
                raise LinkError(str(ep), f"cannot open: {exc}") from exc
            self._failed(exc)
        if self._keeper is None:
            self._keeper = asyncio.get_running_loop().create_task(
                self._keep_open(), name=f"link-{ep}"
            )

    def _open_udp(
        self,
        on_chunk: OnChunk,
        rcvbuf: int,
        batch: int,
        on_burst: Callable[[], None] | None,
    ) -> None:
        ep = self.endpoint
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
        asyncio.get_running_loop().add_reader(
            sock.fileno(), self._read_udp, sock, on_chunk, max(1, batch), on_burst
        )

    async def _open_stream(self) -> None:
        """One attempt to open the TCP connection or the serial device; OSError if not."""
        ep = self.endpoint
        on_chunk = self._on_chunk
        assert on_chunk is not None
        if ep.kind is EndpointKind.TCP:
            peer = (ep.host, ep.port)
            connect = asyncio.get_running_loop().create_connection(
                lambda: _Stream(on_chunk, peer), ep.host, ep.port
            )
            try:
                tr2, proto = await asyncio.wait_for(connect, _CONNECT_TIMEOUT_S)
            except TimeoutError as exc:
                raise OSError(f"no answer within {_CONNECT_TIMEOUT_S:g} s") from exc
            self._tcp = tr2
            self._stream = proto
            self.default_peer = peer
            self.local_port = int(tr2.get_extra_info("sockname")[1])
        else:
            self._open_serial(on_chunk)
        self.connects += 1
        self.failures = 0
        self.last_error = ""
        self.up = True
        if self.connects > 1 or self.backoff is not None:
            _log.info("link %s up (connection %d)", ep, self.connects)
        self._report(True)

    def _failed(self, exc: BaseException) -> None:
        self.failures += 1
        self.last_error = str(exc) or type(exc).__name__
        assert self.backoff is not None
        wait_s = self.backoff.delay_s(self.failures)
        if self.failures == 1:
            _log.warning(
                "link %s not up: %s; retrying in %.1f s, then up to every %.1f s",
                self.endpoint,
                self.last_error,
                wait_s,
                self.backoff.max_s,
            )
        else:
            self._ratelog.info(
                "retry",
                "link %s still not up after %d attempts: %s",
                self.endpoint,
                self.failures,
                self.last_error,
            )

    def _lost(self, reason: str) -> None:
        """The open stream link closed (peer gone, device error)."""
        if not self.up:
            return
        self.up = False
        self.last_error = reason
        self._close_stream()
        _log.warning("link %s down: %s", self.endpoint, reason)
        self._report(False)

    def _report(self, up: bool) -> None:
        if self._on_state is not None:
            try:
                self._on_state(up)
            except Exception:  # a listener bug must not stop the reconnects
                _log.exception("link %s state callback failed", self.endpoint)

    async def _keep_open(self) -> None:
        """Watch a stream link: when it closes, reopen it with backoff (without a backoff:
        report it down and stop)."""
        while not self._closing:
            if self.up:
                await self._wait_closed()
                continue
            if self.backoff is None:
                return
            await asyncio.sleep(self.backoff.delay_s(max(self.failures, 1)))
            if self._closing:
                return
            try:
                await self._open_stream()
            except OSError as exc:
                self._failed(exc)

    async def _wait_closed(self) -> None:
        if self._stream is not None:
            exc = await self._stream.closed
            self._lost(f"connection closed ({exc})" if exc else "connection closed by peer")
        elif self._serial_closed is not None:
            await self._serial_closed
            self._lost(self.last_error or "serial device closed")
        else:  # not reached: an open stream link has one of the two
            self._lost("no stream")

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
        loop = asyncio.get_running_loop()
        self._fd = fd
        closed: asyncio.Future[None] = loop.create_future()
        self._serial_closed = closed
        peer = (ep.device, ep.baud)
        self.default_peer = peer

        def gone(reason: str) -> None:
            with contextlib.suppress(RuntimeError, ValueError):
                loop.remove_reader(fd)
            self.last_error = reason
            if not closed.done():
                closed.set_result(None)

        def readable() -> None:
            try:
                data = os.read(fd, 65536)
            except BlockingIOError:
                return
            except OSError as exc:  # EIO: the device went away (USB unplugged, pty closed)
                gone(f"read failed: {exc}")
                return
            if not data:
                gone("end of file")
                return
            on_chunk(data, peer)

        loop.add_reader(fd, readable)

    def send(self, data: bytes, addr: Address | None) -> None:
        """Send one frame; to ``addr`` on UDP (or the udpout peer). Never raises: a failed
        send is counted (the protocol layers retry); on a stream link that is down the frame
        is dropped and counted in ``dropped_down``."""
        try:
            if self._sock is not None:
                dest = addr or self.default_peer
                if dest is not None:
                    self._sock.sendto(data, dest)
            elif self._tcp is not None and not self._tcp.is_closing():
                self._tcp.write(data)
            elif self._fd >= 0:
                os.write(self._fd, data)
            elif not self.datagram:
                self.dropped_down += 1
        except OSError as exc:
            self.errors[0] += 1
            self._ratelog.log(logging.DEBUG, "send", "send on %s failed: %s", self.endpoint, exc)

    def _close_stream(self) -> None:
        if self._tcp is not None:
            self._tcp.close()
            self._tcp = None
            self._stream = None
        self._serial_closed = None
        if self._fd >= 0:
            with contextlib.suppress(RuntimeError, ValueError):
                asyncio.get_running_loop().remove_reader(self._fd)
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = -1

    def close(self) -> None:
        self._closing = True
        self.up = False
        if self._keeper is not None:
            self._keeper.cancel()
            self._keeper = None
        if self._sock is not None:
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                asyncio.get_running_loop().remove_reader(self._sock.fileno())
            self._sock.close()
            self._sock = None
        self._close_stream()
