"""Recording every MAVLink link to ``.tlog`` files: ``MavlinkHub(..., raw_tap=recorder.tap)``.

:meth:`LinkRecorder.tap` runs on the event loop for every received chunk and every sent frame:
it only appends to a bounded queue (drop-and-count when full: recording must never slow the
link down). One background thread splits chunks into MAVLink packets and writes them with
:class:`adapters.tlog.TlogWriter`, one file per link named from the link string (sanitised)
and the recorder's start time, e.g. ``udpin_127.0.0.1_14550-20260123T105703Z.tlog``.

A tlog record is one MAVLink packet, but a UDP datagram may hold several frames and a TCP or
serial chunk may end inside one. :func:`split_packets` frames by the MAVLink v1/v2 length
fields and accepts a frame only when its CRC checks (or when the message id is unknown to the
dialect, as the tlog reader does); other bytes are skipped one at a time and counted. A frame
left incomplete at the end of a chunk is carried over to the next chunk of the same link
(streams), but dropped and counted for UDP links (MAVLink never splits a frame across
datagrams). So record -> replay gives back exactly the frames that were on the wire.
"""

from __future__ import annotations

import logging
import queue
import re
import threading
import time
from dataclasses import dataclass, fields
from pathlib import Path

from adapters.mavlink import MavlinkHub
from adapters.tlog import TlogWriter
from adapters.tlog._mavlink import crc_extra, x25

_log = logging.getLogger(__name__)

_V1, _V2 = 0xFE, 0xFD
_SIGNED = 0x01
_MAX_FRAME = 12 + 255 + 13  # MAVLink 2 header + max payload + signature (+ CRC in the 12)


@dataclass(slots=True)
class RecorderCounters:
    chunks: int = 0
    packets: int = 0
    dropped_chunks: int = 0  # queue full
    skipped_bytes: int = 0  # not part of a valid frame
    truncated: int = 0  # frames cut at the end of a UDP datagram
    write_errors: int = 0
    files: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: int(getattr(self, f.name)) for f in fields(self)}


def _frame_len(buf: bytes | bytearray, i: int) -> int | None:
    """Length of the frame whose magic byte is ``buf[i]``; None when it is not a magic byte.
    Without the length bytes the minimum length is returned: it exceeds the buffer."""
    magic = buf[i]
    if magic == _V1:
        return 8 + buf[i + 1] if i + 1 < len(buf) else 8
    if magic == _V2:
        if i + 2 >= len(buf):
            return 12
        return 12 + buf[i + 1] + (13 if buf[i + 2] & _SIGNED else 0)
    return None


def _crc_ok(frame: bytes | bytearray) -> bool:
    if frame[0] == _V2:
        header = 10
        msgid = frame[7] | (frame[8] << 8) | (frame[9] << 16)
    else:
        header = 6
        msgid = frame[5]
    extra = crc_extra(msgid)
    if extra is None:
        return True  # unknown to the dialect: keep it (the reader does the same)
    end = header + frame[1]
    return x25(bytes(frame[1:end]) + bytes([extra])) == frame[end] | (frame[end + 1] << 8)


def split_packets(data: bytes | bytearray) -> tuple[list[bytes], int, int]:
    """Pure: ``(packets, skipped_bytes, rest)`` of one chunk. ``rest`` is the start index of
    an incomplete frame at the end (``len(data)`` when there is none)."""
    out: list[bytes] = []
    skipped = 0
    i = 0
    n = len(data)
    while i < n:
        length = _frame_len(data, i)
        if length is None:
            skipped += 1
            i += 1
            continue
        if i + length > n:  # also when the length byte itself is not there yet
            return out, skipped, i
        frame = bytes(data[i : i + length])
        if _crc_ok(frame):
            out.append(frame)
            i += length
        else:
            skipped += 1
            i += 1
    return out, skipped, n


def sanitise(link: str) -> str:
    """A file-name-safe form of a link string (``udpin:127.0.0.1:14550`` ->
    ``udpin_127.0.0.1_14550``)."""
    text = re.sub(r"[^A-Za-z0-9.\-]+", "_", link).strip("_.")
    return text or "link"


def record_links(hub: MavlinkHub, folder: Path | None) -> LinkRecorder | None:
    """``serve``/``run --record DIR``: every link of ``hub``, received and sent, recorded to
    ``folder`` (None: nothing recorded). The caller closes the recorder after the hub."""
    if folder is None:
        return None
    recorder = LinkRecorder(folder)
    hub.raw_tap = recorder.tap
    _log.info("recording every MAVLink link to %s", folder)
    return recorder


class LinkRecorder:
    """See the module docstring. ``tap`` is thread-safe and never blocks."""

    def __init__(
        self,
        folder: Path,
        *,
        max_queue: int = 10_000,
        start_t_s: float | None = None,
    ) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.folder = folder
        self.counters = RecorderCounters()
        t0 = time.time() if start_t_s is None else start_t_s
        self._stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(t0))
        self._queue: queue.Queue[tuple[str, bytes, float] | None] = queue.Queue(maxsize=max_queue)
        self._writers: dict[str, TlogWriter] = {}
        self._carry: dict[str, bytearray] = {}
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="tlog-recorder", daemon=True)
        self._thread.start()

    @property
    def files(self) -> dict[str, Path]:
        """Link -> file (links seen so far by the writer thread)."""
        return {link: w.path for link, w in list(self._writers.items())}

    def tap(self, link: str, data: bytes, t_s: float) -> None:
        """The hub's ``raw_tap``: queue one chunk (drop-and-count when the queue is full)."""
        if self._closed:
            return
        try:
            self._queue.put_nowait((link, bytes(data), t_s))
        except queue.Full:
            self.counters.dropped_chunks += 1
            if self.counters.dropped_chunks in (1, 100, 10_000):
                _log.warning(
                    "tlog recorder queue full: %d chunks dropped", self.counters.dropped_chunks
                )

    def close(self, timeout_s: float = 10.0) -> None:
        """Write everything queued, flush and close every file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            _log.error("tlog recorder did not finish within %.1f s", timeout_s)

    def __enter__(self) -> LinkRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- writer thread -----------------------------------------------------------------------
    def _writer(self, link: str) -> TlogWriter:
        w = self._writers.get(link)
        if w is None:
            path = self.folder / f"{sanitise(link)}-{self._stamp}.tlog"
            n = 1
            while path.exists():
                n += 1
                path = self.folder / f"{sanitise(link)}-{self._stamp}-{n}.tlog"
            w = self._writers[link] = TlogWriter(path)
            self.counters.files += 1
            _log.info("recording %s to %s", link, path)
        return w

    def _write(self, link: str, data: bytes, t_s: float) -> None:
        c = self.counters
        c.chunks += 1
        carry = self._carry.get(link)
        buf = carry + data if carry else data
        packets, skipped, rest = split_packets(buf)
        c.skipped_bytes += skipped
        tail = buf[rest:]
        if tail:
            if link.startswith("udp") or len(tail) >= _MAX_FRAME:
                c.truncated += 1
                c.skipped_bytes += len(tail)
                self._carry.pop(link, None)
            else:
                self._carry[link] = bytearray(tail)
        else:
            self._carry.pop(link, None)
        if not packets:
            return
        w = self._writer(link)
        for p in packets:
            w.write(t_s, p)
        c.packets += len(packets)

    def _run(self) -> None:
        try:
            while True:
                item = self._queue.get()
                if item is None:  # close()
                    return
                link, data, t_s = item
                try:
                    self._write(link, data, t_s)
                except OSError:
                    self.counters.write_errors += 1
                    _log.exception("tlog recorder: cannot write %s", link)
        finally:
            for w in self._writers.values():
                try:
                    w.close()
                except OSError:
                    self.counters.write_errors += 1
                    _log.exception("tlog recorder: cannot close %s", w.path)
