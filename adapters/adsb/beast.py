"""Beast binary framing (dump1090 port 30005), pure and incremental.

A frame is ``0x1a TYPE body`` where the body is a 6-byte big-endian MLAT counter, one signal
byte and the payload (type ``'1'`` Mode A/C: 2 bytes, ``'2'`` Mode-S short: 7, ``'3'``
Mode-S long: 14, ``'4'`` status). A literal 0x1a inside the body is sent twice. A body cut
short by an unescaped 0x1a is a truncated frame: it is dropped, counted, and parsing resumes at
that marker. Bytes between frames are skipped and counted.
"""

from __future__ import annotations

from dataclasses import dataclass

_ESC = 0x1A
# TYPE byte -> payload length in bytes
_PAYLOAD_LEN = {0x31: 2, 0x32: 7, 0x33: 14, 0x34: 14}
_HEADER_LEN = 7  # MLAT (6) + signal (1)
_MAX_BUFFER = 64 * 1024  # a garbage stream without markers must not grow memory


@dataclass(frozen=True, slots=True, kw_only=True)
class BeastFrame:
    """One Mode-S frame: ``mlat_ticks`` is the receiver's free-running counter (12 MHz on
    dump1090), ``signal`` the raw RSSI byte, ``hex`` the payload in upper-case hex."""

    mlat_ticks: int
    signal: int
    hex: str


@dataclass(slots=True)
class BeastCounters:
    frames: int = 0
    mode_ac: int = 0
    status: int = 0
    truncated: int = 0
    bad_type: int = 0
    skipped_bytes: int = 0


class BeastFramer:
    """Feed bytes in any chunking; get back complete Mode-S frames."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.counters = BeastCounters()

    def reset(self) -> None:
        """Drop a partial frame (counted as truncated), e.g. after a reconnect."""
        if self._buf:
            self.counters.truncated += 1
            self._buf.clear()

    def feed(self, data: bytes) -> list[BeastFrame]:
        self._buf += data
        buf = self._buf
        out: list[BeastFrame] = []
        i = 0
        n = len(buf)
        while i < n:
            if buf[i] != _ESC:
                j = buf.find(_ESC, i)
                stop = n if j < 0 else j
                self.counters.skipped_bytes += stop - i
                i = stop
                continue
            if i + 1 >= n:
                break  # need the type byte
            kind = buf[i + 1]
            payload_len = _PAYLOAD_LEN.get(kind)
            if payload_len is None:
                # 0x1a 0x1a outside a body, or an unknown type: not a frame start
                self.counters.bad_type += 1
                i += 1 if kind == _ESC else 2
                continue
            body, nxt = _unescape(buf, i + 2, _HEADER_LEN + payload_len)
            if nxt == -1:
                break  # incomplete: wait for more bytes
            if body is None:
                self.counters.truncated += 1
                i = nxt
                continue
            i = nxt
            if kind == 0x31:
                self.counters.mode_ac += 1
                continue
            if kind == 0x34:
                self.counters.status += 1
                continue
            self.counters.frames += 1
            out.append(
                BeastFrame(
                    mlat_ticks=int.from_bytes(body[0:6], "big"),
                    signal=body[6],
                    hex=body[_HEADER_LEN:].hex().upper(),
                )
            )
        del buf[:i]
        if len(buf) > _MAX_BUFFER:
            self.counters.skipped_bytes += len(buf)
            buf.clear()
        return out


def _unescape(buf: bytearray, start: int, length: int) -> tuple[bytes | None, int]:
    """Read ``length`` unescaped bytes from ``start``. Returns (body, next index);
    (None, marker index) when an unescaped 0x1a cuts the body; (None, -1) when more bytes
    are needed."""
    body = bytearray()
    j = start
    n = len(buf)
    while len(body) < length:
        if j >= n:
            return None, -1
        b = buf[j]
        if b == _ESC:
            if j + 1 >= n:
                return None, -1
            if buf[j + 1] != _ESC:
                return None, j
            j += 2
        else:
            j += 1
        body.append(b)
    return bytes(body), j
