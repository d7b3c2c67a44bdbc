"""Reading ``.tlog`` files: records of an 8-byte big-endian microsecond UNIX timestamp followed
by one MAVLink packet (v1 ``0xFE`` or v2 ``0xFD``), as QGroundControl and MAVProxy write them.

The framing core (:func:`scan_records`) is pure: bytes in, records and counters out. A record
is accepted only when its packet is complete and its CRC checks against the dialect's
CRC_EXTRA (or, for a message id the dialect does not know, when its timestamp is plausible).
Anything else is corrupt: the scanner advances one byte, resynchronises on the next valid
record, and counts one corrupt chunk plus the skipped bytes. A truncated last record (a crash
while writing) is counted in ``truncated_tail``, never raised.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, fields
from pathlib import Path

from adapters.tlog._mavlink import crc_extra, x25

_TS_LEN = 8
_V1, _V2 = 0xFE, 0xFD
_V2_SIGNED = 0x01
_SIGNATURE_LEN = 13
_CHUNK = 256 * 1024
# Timestamps outside 2000-01-01 .. 2100-01-01 are not a tlog record start.
_MIN_US = 946_684_800 * 1_000_000
_MAX_US = 4_102_444_800 * 1_000_000
# A record more than this far from the previous one (either way) is a false resync: real
# tlogs are monotonic except for small clock steps.
_MAX_JUMP_US = 3600 * 1_000_000


@dataclass(frozen=True, slots=True)
class TlogRecord:
    """One record: ``t_s`` POSIX seconds (the logger's receive time), the raw packet."""

    t_s: float
    packet: bytes

    @property
    def msgid(self) -> int:
        return packet_msgid(self.packet)


@dataclass(slots=True)
class TlogCounters:
    records: int = 0
    corrupt_chunks: int = 0
    skipped_bytes: int = 0
    unknown_msgid: int = 0
    truncated_tail: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: int(getattr(self, f.name)) for f in fields(self)}


def packet_msgid(packet: bytes) -> int:
    if packet[0] == _V2:
        return packet[7] | (packet[8] << 8) | (packet[9] << 16)
    return packet[5]


def _packet_len(buf: bytes | bytearray, i: int) -> int | None:
    """Length of the packet starting at ``buf[i]`` (magic byte), None if not a magic byte.
    May exceed the buffer: the caller checks."""
    magic = buf[i]
    if magic == _V1:
        return 8 + buf[i + 1] if i + 1 < len(buf) else 8
    if magic == _V2:
        if i + 2 >= len(buf):
            return 12
        signed = _SIGNATURE_LEN if buf[i + 2] & _V2_SIGNED else 0
        return 12 + buf[i + 1] + signed
    return None


def _check(packet: bytes) -> bool | None:
    """True if the CRC matches, False if not, None if the message id is unknown."""
    if packet[0] == _V2:
        header, payload_len = 10, packet[1]
    else:
        header, payload_len = 6, packet[1]
    extra = crc_extra(packet_msgid(packet))
    if extra is None:
        return None
    end = header + payload_len
    crc = x25(bytes(packet[1:end]) + bytes([extra]))
    return crc == packet[end] | (packet[end + 1] << 8)


class _Scanner:
    """Incremental record framing over a growing buffer."""

    def __init__(self) -> None:
        self.counters = TlogCounters()
        self._last_us: int | None = None
        self._in_corrupt = False

    def _plausible(self, us: int) -> bool:
        if not _MIN_US <= us <= _MAX_US:
            return False
        return self._last_us is None or abs(us - self._last_us) <= _MAX_JUMP_US

    def _skip(self) -> None:
        self.counters.skipped_bytes += 1
        if not self._in_corrupt:
            self._in_corrupt = True
            self.counters.corrupt_chunks += 1

    def scan(self, buf: bytearray, final: bool) -> tuple[list[TlogRecord], int]:
        """Records in ``buf`` and how many bytes were consumed. With ``final`` the tail that
        cannot complete is counted as truncated and consumed."""
        out: list[TlogRecord] = []
        i = 0
        n = len(buf)
        while n - i > _TS_LEN:
            us = int.from_bytes(buf[i : i + _TS_LEN], "big")
            j = i + _TS_LEN
            plen = _packet_len(buf, j)
            if plen is None or not self._plausible(us):
                self._skip()
                i += 1
                continue
            if j + plen > n or j + 2 >= n:
                if not final:
                    break  # wait for more bytes
                # the tail cannot complete: a truncated last record, or garbage
                self.counters.truncated_tail += 1
                self.counters.skipped_bytes += n - i
                i = n
                break
            packet = bytes(buf[j : j + plen])
            ok = _check(packet)
            if ok is False:
                self._skip()
                i += 1
                continue
            if ok is None:
                self.counters.unknown_msgid += 1
            self._in_corrupt = False
            self._last_us = us
            self.counters.records += 1
            out.append(TlogRecord(us / 1e6, packet))
            i = j + plen
        if final and i < n:
            self.counters.truncated_tail += 1
            self.counters.skipped_bytes += n - i
            i = n
        return out, i


def scan_records(data: bytes) -> tuple[list[TlogRecord], TlogCounters]:
    """Pure: all records of a complete tlog image, with counters."""
    scanner = _Scanner()
    records, _ = scanner.scan(bytearray(data), final=True)
    return records, scanner.counters


class TlogReader:
    """Iterate the records of a ``.tlog`` file, reading it in chunks. ``counters`` is updated
    as records are read (complete once iteration ends)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._scanner = _Scanner()

    @property
    def counters(self) -> TlogCounters:
        return self._scanner.counters

    def __iter__(self) -> Iterator[TlogRecord]:
        buf = bytearray()
        with self.path.open("rb") as f:
            while True:
                chunk = f.read(_CHUNK)
                buf += chunk
                records, used = self._scanner.scan(buf, final=not chunk)
                del buf[:used]
                yield from records
                if not chunk:
                    return
