"""ADS-B receiver captures on disk: the bytes of a feed as received, plus a timing sidecar.

Written by the recorder (``serve``/``run --record``, :class:`CaptureWriter`), read back by
``gcs-utm replay`` (:func:`iter_capture`). A capture of one feed is one or more pieces (the
recorder rotates files by size and time), each a data file and, when recorded by us, its
sidecar:

- ``<name>.sbs`` (SBS-1 BaseStation text), ``<name>.avr`` (AVR text) or ``<name>.bin``
  (Beast binary): the bytes exactly as they came off the TCP connection;
- ``<name>.<ext>.times``: one text line per received chunk, ``<receipt time in integer
  microseconds since the UNIX epoch> <end offset of the chunk in the data file> <1 for the
  first chunk of a new connection, else 0>``.

Timing on replay (the receipt time handed to the decoder, which the replay also uses as the
event time):

- **with the sidecar** every chunk is decoded at its receipt time, with the line buffer and
  the Beast framer reset at each new connection, exactly as the live feed decoded it: the
  measurements are the ones the live service had;
- **SBS-1 without it**: a line's "message generated" date/time (fields 7-8, read as UTC) is
  its receipt time; a line without one takes the previous line's time (the first time, for
  lines before it); a capture without any time is refused (:class:`CaptureError`);
- **Beast without it**: the receiver's 12 MHz MLAT counter gives times relative to the first
  frame: ``start_t_s + (ticks - first ticks) / 12 MHz``; a counter that goes backwards or
  stops (a receiver restart, a receiver that sends 0) keeps the previous frame's time and
  re-anchors there (counted ``mlat_resets``). ``start_t_s`` is chosen by the caller;
- **AVR without it**: ``@``-lines carry the same MLAT counter as Beast; ``*``-lines take the
  previous line's time (``start_t_s`` for the first).

Data bytes beyond the sidecar's last offset (a crash between the two writes) are decoded at
the last recorded time and counted ``untimed_tail_bytes``.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import BinaryIO, TextIO

from adapters.adsb.modes import ModeSDecoder
from adapters.adsb.sbs import SbsDecoder, sbs_line_time
from gcs_utm.model import Measurement

MLAT_HZ = 12_000_000.0  # dump1090/readsb Beast and AVR '@' timestamps: a 12 MHz counter
MAX_LINE_BYTES = 4096  # longer than any SBS/AVR line: a stream without newlines is not text
TIMES_SUFFIX = ".times"
_BLOCK = 64 * 1024  # bytes read at a time: memory stays bounded whatever the capture's size
_MAX_UNTIMED_HEAD = 10_000  # SBS lines waiting for a first date/time before giving up


class CaptureKind(enum.Enum):
    SBS = "sbs"
    AVR = "avr"
    BEAST = "beast"

    @property
    def extension(self) -> str:
        return ".bin" if self is CaptureKind.BEAST else f".{self.value}"


CAPTURE_SUFFIXES: dict[str, CaptureKind] = {
    ".sbs": CaptureKind.SBS,
    ".avr": CaptureKind.AVR,
    ".bin": CaptureKind.BEAST,
    ".beast": CaptureKind.BEAST,
}


class CaptureError(ValueError):
    """A capture that cannot be replayed; ``path`` and ``message`` say what was wrong."""

    def __init__(self, path: Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


def capture_kind(path: Path) -> CaptureKind | None:
    """The kind of a capture file by its suffix (None: not a capture)."""
    return CAPTURE_SUFFIXES.get(path.suffix.lower())


def times_path(path: Path) -> Path:
    return path.with_name(path.name + TIMES_SUFFIX)


# ---- writing ---------------------------------------------------------------------------------


class CaptureWriter:
    """Append-only writer of one capture piece and its sidecar. Blocking file I/O: the
    recorder calls it from its thread. Data and sidecar are flushed together every
    ``flush_interval_s`` of receipt time (and on :meth:`flush`/:meth:`close`); the data goes
    first, so a crash leaves at most data without a time (see the module docstring)."""

    def __init__(self, path: Path, *, flush_interval_s: float = 1.0) -> None:
        self.path = path
        self._data: BinaryIO | None = path.open("wb")
        try:
            self._times: TextIO = times_path(path).open("w", encoding="ascii")
        except OSError:
            self._data.close()
            raise
        self._flush_interval_s = flush_interval_s
        self._last_flush_t_s: float | None = None
        self.size_bytes = 0
        self.chunks = 0

    def write(self, t_s: float, data: bytes, *, new_connection: bool = False) -> None:
        if self._data is None:
            raise ValueError(f"{self.path}: capture writer is closed")
        self._data.write(data)
        self.size_bytes += len(data)
        self.chunks += 1
        self._times.write(f"{round(t_s * 1e6)} {self.size_bytes} {int(new_connection)}\n")
        if self._last_flush_t_s is None:
            self._last_flush_t_s = t_s
        elif t_s - self._last_flush_t_s >= self._flush_interval_s:
            self.flush()
            self._last_flush_t_s = t_s

    def flush(self) -> None:
        if self._data is None:
            return
        self._data.flush()
        self._times.flush()

    def close(self) -> None:
        if self._data is None:
            return
        try:
            self.flush()
        finally:
            self._data.close()
            self._times.close()
            self._data = None


# ---- reading ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Chunk:
    t_s: float
    data: bytes
    new_connection: bool


@dataclass(slots=True)
class CaptureCounters:
    pieces: int = 0
    chunks: int = 0
    bytes: int = 0
    untimed_tail_bytes: int = 0
    untimed_lines: int = 0  # SBS/AVR lines without a time of their own (previous time used)
    mlat_resets: int = 0
    overlong_lines: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: int(getattr(self, f.name)) for f in fields(self)}


def read_chunks(path: Path, counters: CaptureCounters | None = None) -> Iterator[Chunk]:
    """The chunks of a capture piece recorded with its sidecar (see the module docstring),
    read as they are handed on (memory: one chunk). Raises :class:`CaptureError` naming the
    sidecar line that is malformed."""
    c = counters if counters is not None else CaptureCounters()
    side = times_path(path)
    size = path.stat().st_size
    start = 0
    t_s = 0.0
    with path.open("rb") as data, side.open(encoding="ascii", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            t_s, end, new = _times_line(side, lineno, line, start, size)
            c.chunks += 1
            c.bytes += end - start
            yield Chunk(t_s, data.read(end - start), new)
            start = end
        while tail := data.read(_BLOCK):
            c.untimed_tail_bytes += len(tail)
            c.bytes += len(tail)
            yield Chunk(t_s, tail, start == 0)
            start += len(tail)


def _times_line(
    side: Path, lineno: int, line: str, start: int, size: int
) -> tuple[float, int, bool]:
    parts = line.split()
    try:
        t_us, end, new = int(parts[0]), int(parts[1]), int(parts[2])
    except (IndexError, ValueError):
        raise CaptureError(
            side, f"line {lineno}: expected '<t_us> <end offset> <0|1>', got {line.strip()!r}"
        ) from None
    if not start <= end <= size:
        raise CaptureError(
            side,
            f"line {lineno}: end offset {end} outside {start}..{size} (sidecar of another file?)",
        )
    return t_us / 1e6, end, new == 1


class LineSplitter:
    """Bytes of a text feed -> lines, as the live reader splits them: a line cut by a
    reconnect is dropped, an overlong partial line (not text) is dropped and counted."""

    def __init__(self) -> None:
        self._buf = b""
        self.overlong_lines = 0

    def feed(self, data: bytes, *, new_connection: bool = False) -> list[str]:
        if new_connection:
            self._buf = b""
        *lines, self._buf = (self._buf + data).split(b"\n")
        if len(self._buf) > MAX_LINE_BYTES:
            self.overlong_lines += 1
            self._buf = b""
        return [raw.decode("ascii", "replace").rstrip("\r") for raw in lines]

    def flush(self) -> list[str]:
        """The last line of a stream that ended without its newline."""
        rest, self._buf = self._buf, b""
        return [rest.decode("ascii", "replace").rstrip("\r")] if rest.strip() else []


class CaptureDecoder:
    """One feed's decoder fed from a capture; see :func:`iter_capture`."""

    def __init__(self, kind: CaptureKind, decoder: SbsDecoder | ModeSDecoder) -> None:
        if (kind is CaptureKind.SBS) != isinstance(decoder, SbsDecoder):
            raise ValueError(f"a {kind.value} capture needs the matching decoder")
        self.kind = kind
        self.decoder = decoder
        self.counters = CaptureCounters()
        self._lines = LineSplitter()

    def feed_chunk(self, chunk: Chunk) -> list[Measurement]:
        """One recorded chunk, decoded as the live feed decoded it."""
        dec = self.decoder
        if self.kind is CaptureKind.BEAST:
            assert isinstance(dec, ModeSDecoder)
            if chunk.new_connection:
                dec.reset_stream()
            return dec.feed_beast(chunk.data, chunk.t_s)
        out: list[Measurement] = []
        for line in self._lines.feed(chunk.data, new_connection=chunk.new_connection):
            m = self.feed_line(line, chunk.t_s)
            if m is not None:
                out.append(m)
        self.counters.overlong_lines = self._lines.overlong_lines
        return out

    def feed_line(self, line: str, t_s: float) -> Measurement | None:
        """One SBS/AVR line received at ``t_s``."""
        if isinstance(self.decoder, SbsDecoder):
            return self.decoder.feed(line, t_s)
        if not line.strip():
            return None
        return self.decoder.feed_avr(line, t_s)


def iter_capture(
    pieces: Sequence[Path], decoder: CaptureDecoder, *, start_t_s: float = 0.0
) -> Iterator[tuple[float, Measurement]]:
    """``(receipt t_s, measurement)`` of one feed's capture, its pieces in order. Pieces with
    a sidecar are timed by it, the others by their content (module docstring); ``start_t_s``
    anchors MLAT times and untimed first lines. Raises :class:`CaptureError`."""
    last_t_s = start_t_s
    for path in pieces:
        decoder.counters.pieces += 1
        if times_path(path).is_file():
            for chunk in read_chunks(path, decoder.counters):
                last_t_s = chunk.t_s
                for m in decoder.feed_chunk(chunk):
                    yield chunk.t_s, m
        else:
            timed = _untimed(path, decoder, last_t_s)
            for t_s, m in timed:
                last_t_s = t_s
                yield t_s, m


def _blocks(path: Path) -> Iterator[bytes]:
    with path.open("rb") as f:
        while block := f.read(_BLOCK):
            yield block


def _lines(path: Path, counters: CaptureCounters) -> Iterator[str]:
    """The lines of a text capture, split as the live reader splits them (the last line
    may lack its newline)."""
    splitter = LineSplitter()
    for block in _blocks(path):
        yield from splitter.feed(block)
    yield from splitter.flush()
    counters.overlong_lines += splitter.overlong_lines


def _untimed(
    path: Path, decoder: CaptureDecoder, start_t_s: float
) -> Iterator[tuple[float, Measurement]]:
    decoder.counters.chunks += 1
    decoder.counters.bytes += path.stat().st_size
    if decoder.kind is CaptureKind.BEAST:
        yield from _beast_by_mlat(path, decoder, start_t_s)
    elif decoder.kind is CaptureKind.SBS:
        yield from _sbs_by_line_time(path, decoder)
    else:
        yield from _avr_by_mlat(path, decoder, start_t_s)


class _MlatClock:
    """12 MHz MLAT ticks -> seconds from an anchor; re-anchors when the counter goes back."""

    def __init__(self, start_t_s: float, counters: CaptureCounters) -> None:
        self.t_s = start_t_s
        self._anchor: tuple[int, float] | None = None
        self._last_ticks = -1
        self._counters = counters

    def at(self, ticks: int) -> float:
        if self._anchor is None:
            self._anchor = (ticks, self.t_s)
        elif ticks < self._last_ticks or ticks == 0:
            self._counters.mlat_resets += 1
            self._anchor = (ticks, self.t_s)
        self._last_ticks = ticks
        anchor_ticks, anchor_t_s = self._anchor
        self.t_s = anchor_t_s + (ticks - anchor_ticks) / MLAT_HZ
        return self.t_s


def _beast_by_mlat(
    path: Path, decoder: CaptureDecoder, start_t_s: float
) -> Iterator[tuple[float, Measurement]]:
    dec = decoder.decoder
    assert isinstance(dec, ModeSDecoder)
    clock = _MlatClock(start_t_s, decoder.counters)
    for block in _blocks(path):
        for frame in dec.beast_frames(block):  # framed by the decoder: counted where live
            t_s = clock.at(frame.mlat_ticks)
            m = dec.feed_hex(frame.hex, t_s)
            if m is not None:
                yield t_s, m


def _sbs_by_line_time(path: Path, decoder: CaptureDecoder) -> Iterator[tuple[float, Measurement]]:
    """Lines before the first line with a date/time take that first time."""
    c = decoder.counters
    t_s: float | None = None
    pending: list[str] = []
    for line in _lines(path, c):
        own = sbs_line_time(line)
        if own is None and line.strip():
            c.untimed_lines += 1
        if own is not None:
            if t_s is None:  # the lines waiting for a first time get it
                yield from _feed_lines(decoder, pending, own)
                pending = []
            t_s = own
        if t_s is None:
            if len(pending) >= _MAX_UNTIMED_HEAD:
                break
            pending.append(line)
            continue
        yield from _feed_lines(decoder, (line,), t_s)
    if t_s is None:
        raise CaptureError(
            path,
            "no SBS-1 line carries a date/time (in the first "
            f"{_MAX_UNTIMED_HEAD} lines) and there is no .times sidecar: nothing to time "
            "the capture by",
        )


def _feed_lines(
    decoder: CaptureDecoder, lines: Sequence[str], t_s: float
) -> Iterator[tuple[float, Measurement]]:
    for line in lines:
        m = decoder.feed_line(line, t_s)
        if m is not None:
            yield t_s, m


def _avr_by_mlat(
    path: Path, decoder: CaptureDecoder, start_t_s: float
) -> Iterator[tuple[float, Measurement]]:
    clock = _MlatClock(start_t_s, decoder.counters)
    for line in _lines(path, decoder.counters):
        text = line.strip()
        if text.startswith("@") and len(text) > 13:
            try:
                t_s = clock.at(int(text[1:13], 16))
            except ValueError:
                t_s = clock.t_s  # the decoder counts the line malformed
        else:
            t_s = clock.t_s
            if text:
                decoder.counters.untimed_lines += 1
        m = decoder.feed_line(line, t_s)
        if m is not None:
            yield t_s, m
