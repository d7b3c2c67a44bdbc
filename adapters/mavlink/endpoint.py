"""Connection strings as users know them from pymavlink/MAVProxy, parsed into :class:`Endpoint`.

Accepted: ``udpin:HOST:PORT`` (also ``udp:``), ``udpout:HOST:PORT`` (also ``udpbcast:``
is not supported), ``tcp:HOST:PORT``, ``serial:/dev/ttyX:BAUD``, ``/dev/ttyX:BAUD`` and
``/dev/ttyX,BAUD`` (MAVProxy), ``COM3:57600``. Port 0 with ``udpin`` binds an ephemeral port.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class EndpointError(ValueError):
    """A connection string that cannot be used; ``part`` names the bad piece."""

    def __init__(self, text: str, part: str, message: str) -> None:
        super().__init__(f"connection string {text!r}: {part}: {message}")
        self.text = text
        self.part = part
        self.message = message


class EndpointKind(Enum):
    UDPIN = "udpin"
    UDPOUT = "udpout"
    TCP = "tcp"
    SERIAL = "serial"


@dataclass(frozen=True, slots=True, kw_only=True)
class Endpoint:
    kind: EndpointKind
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    def __str__(self) -> str:
        if self.kind is EndpointKind.SERIAL:
            return f"{self.device}:{self.baud}"
        return f"{self.kind.value}:{self.host}:{self.port}"


_BAUDS = (
    1200,
    2400,
    4800,
    9600,
    19200,
    38400,
    57600,
    115200,
    230400,
    460800,
    500000,
    576000,
    921600,
    1000000,
    1500000,
    2000000,
    3000000,
)


def _port(text: str, raw: str, *, allow_zero: bool) -> int:
    try:
        port = int(raw)
    except ValueError as exc:
        raise EndpointError(text, "port", f"expected an integer, got {raw!r}") from exc
    if not (0 if allow_zero else 1) <= port <= 65535:
        raise EndpointError(text, "port", f"out of range: {port}")
    return port


def _serial(text: str, rest: str) -> Endpoint:
    sep = "," if "," in rest else ":"
    device, _, baud_raw = rest.rpartition(sep)
    if not device:
        device, baud_raw = rest, "57600"
    try:
        baud = int(baud_raw)
    except ValueError as exc:
        raise EndpointError(text, "baud", f"expected an integer, got {baud_raw!r}") from exc
    if baud not in _BAUDS:
        raise EndpointError(text, "baud", f"unsupported rate {baud}")
    return Endpoint(kind=EndpointKind.SERIAL, device=device, baud=baud)


def parse_endpoint(text: str) -> Endpoint:
    """Parse one connection string or raise :class:`EndpointError` naming the bad part.

    >>> parse_endpoint("udpin:0.0.0.0:14550")
    Endpoint(kind=<EndpointKind.UDPIN: 'udpin'>, host='0.0.0.0', port=14550, device='', baud=0)
    >>> str(parse_endpoint("/dev/ttyUSB0,57600"))
    '/dev/ttyUSB0:57600'
    """
    s = text.strip()
    if not s:
        raise EndpointError(text, "text", "empty")
    if s.startswith("/dev/") or s.upper().startswith("COM"):
        return _serial(text, s)
    scheme, sep, rest = s.partition(":")
    if not sep:
        raise EndpointError(text, "scheme", "expected SCHEME:HOST:PORT or /dev/ttyX:BAUD")
    scheme = scheme.lower()
    if scheme == "serial":
        return _serial(text, rest)
    kinds = {
        "udpin": EndpointKind.UDPIN,
        "udp": EndpointKind.UDPIN,
        "udpout": EndpointKind.UDPOUT,
        "tcp": EndpointKind.TCP,
    }
    kind = kinds.get(scheme)
    if kind is None:
        raise EndpointError(
            text, "scheme", f"unknown {scheme!r}; expected one of {', '.join(kinds)}, serial"
        )
    host, sep, port_raw = rest.rpartition(":")
    if not sep or not host:
        raise EndpointError(text, "host", "expected HOST:PORT after the scheme")
    host = host.strip("[]")
    port = _port(text, port_raw, allow_zero=kind is EndpointKind.UDPIN)
    return Endpoint(kind=kind, host=host, port=port)
