"""``serve``/``run --record DIR``: every MAVLink link to ``.tlog`` files
(``MavlinkHub(..., raw_tap=recorder.tap)``) and every ADS-B receiver feed to raw capture files
(``SurveillanceService.raw_tap = recorder.tap_feed``), settings ``[record]``.

:meth:`LinkRecorder.tap` and :meth:`LinkRecorder.tap_feed` run on the event loop for every
received chunk and every sent frame: they only append to a bounded queue (drop-and-count when
full: recording must never slow a link down). One background thread splits MAVLink chunks
into packets and writes them with :class:`adapters.tlog.TlogWriter`, and writes feed chunks
as received with :class:`adapters.adsb.capture.CaptureWriter` (plus the ``.times`` sidecar
the replay times them by). Each link or feed is one *stream*, written to files named from
the stream (sanitised link or ``adsb-<kind>_<host>_<port>``) and the record time of the
file's first record, e.g. ``udpin_127.0.0.1_14550-20260123T105703Z.tlog`` or
``adsb-sbs_127.0.0.1_30003-20260123T105703Z.sbs``; a stream starts a new file before one
would grow past ``max_file_mb`` or once it covers ``max_file_s`` of record time.

Failures: :func:`check_folder` refuses, before anything starts, a folder that cannot be
created or written or whose disk has less than ``min_free_mb`` free (:class:`RecordError`, one
line naming the folder). A write that fails later (disk full, folder removed) ends the
recording of that stream only: logged once as an error, counted (``write_errors``, then
``dropped_after_failure``), reported once to ``on_failure`` on the event loop (the service
logs it as a USM event), and the service carries on.

A tlog record is one MAVLink packet, but a UDP datagram may hold several frames and a TCP or
serial chunk may end inside one. :func:`split_packets` frames by the MAVLink v1/v2 length
fields and accepts a frame only when its CRC checks (or when the message id is unknown to the
dialect, as the tlog reader does); other bytes are skipped one at a time and counted. A frame
left incomplete at the end of a chunk is carried over to the next chunk of the same link
(streams), but dropped and counted for UDP links (MAVLink never splits a frame across
datagrams). So record -> replay gives back exactly the frames that were on the wire.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import queue
import re
import shutil
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from adapters.adsb.capture import CaptureKind, CaptureWriter
from adapters.mavlink import MavlinkHub
from adapters.tlog import TlogWriter
from adapters.tlog._mavlink import crc_extra, x25
from gcs_utm.services.record_config import RecordConfig
from gcs_utm.services.surveillance import SurveillanceService

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
    rotations: int = 0  # files closed by size or time to start the next
    feed_chunks: int = 0  # ADS-B feed chunks written
    dropped_after_failure: int = 0  # chunks of a stream whose file could not be written

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


class RecordError(Exception):
    """``--record DIR`` cannot record: the folder and what is wrong with it."""

    def __init__(self, folder: Path, message: str) -> None:
        super().__init__(f"--record {folder}: {message}")
        self.folder = folder
        self.message = message


def check_folder(folder: Path, config: RecordConfig) -> None:
    """Create ``folder`` if needed and check it can be recorded to: writable, with at least
    ``config.min_free_mb`` free. Raises :class:`RecordError`."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordError(folder, f"cannot create the folder: {exc.strerror or exc}") from exc
    if not folder.is_dir():
        raise RecordError(folder, "not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder) as probe:
            probe.write(b"\0" * 4096)
            probe.flush()
    except OSError as exc:
        raise RecordError(folder, f"cannot write in the folder: {exc.strerror or exc}") from exc
    free_mb = shutil.disk_usage(folder).free / 1e6
    if free_mb < config.min_free_mb:
        raise RecordError(
            folder,
            f"only {free_mb:.1f} MB free on its disk, [record] min_free_mb = "
            f"{config.min_free_mb:g}",
        )


def record_links(
    hub: MavlinkHub,
    folder: Path | None,
    config: RecordConfig | None = None,
    *,
    surveillance: SurveillanceService | None = None,
    on_failure: Callable[[str], None] | None = None,
) -> LinkRecorder | None:
    """``serve``/``run --record DIR``: every link of ``hub``, received and sent, and (when
    ``config.adsb``) every feed of ``surveillance``, recorded to ``folder`` (None: nothing
    recorded). Raises :class:`RecordError` when the folder cannot be recorded to. The caller
    closes the recorder after the hub and the feeds."""
    if folder is None:
        return None
    cfg = config or RecordConfig()
    recorder = LinkRecorder(folder, config=cfg, on_failure=on_failure)
    hub.raw_tap = recorder.tap
    if surveillance is not None and cfg.adsb:
        surveillance.raw_tap = recorder.tap_feed
    _log.info(
        "recording every MAVLink link%s to %s (files up to %g MB / %g s)",
        " and ADS-B feed" if surveillance is not None and cfg.adsb else "",
        folder,
        cfg.max_file_mb,
        cfg.max_file_s,
    )
    return recorder


_Writer = TlogWriter | CaptureWriter
_Item = tuple[str, CaptureKind | None, bytes, float, bool]
"""(link or feed, None for a MAVLink link or the feed's capture kind, data, t_s, new
connection)."""


class _Stream:
    """One link or feed, rotated into files by size and time (writer thread only)."""

    def __init__(self, recorder: LinkRecorder, name: str, suffix: str, *, tlog: bool) -> None:
        self.recorder = recorder
        self.name = name
        self.base = sanitise(name)
        self.suffix = suffix
        self.tlog = tlog
        self.writer: _Writer | None = None
        self.size_bytes = 0
        self.start_t_s = 0.0
        self.failed = False
        self.paths: list[Path] = []

    def write(self, t_s: float, data: bytes, *, new_connection: bool = False) -> None:
        n = len(data) + (8 if self.tlog else 0)  # a tlog record = 8-byte time + packet
        cfg = self.recorder.config
        w = self.writer
        if w is not None and (
            (self.size_bytes > 0 and self.size_bytes + n > cfg.max_file_mb * 1e6)
            or t_s - self.start_t_s >= cfg.max_file_s
        ):
            self.close()
            self.recorder.counters.rotations += 1
            w = None
        if w is None:
            w = self._open(t_s)
        if isinstance(w, TlogWriter):
            w.write(t_s, data)
        else:
            w.write(t_s, data, new_connection=new_connection)
        self.size_bytes += n

    def _open(self, t_s: float) -> _Writer:
        folder = self.recorder.folder
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(t_s))
        path = folder / f"{self.base}-{stamp}{self.suffix}"
        n = 1
        while path.exists():
            n += 1
            path = folder / f"{self.base}-{stamp}-{n}{self.suffix}"
        w: _Writer = TlogWriter(path) if self.tlog else CaptureWriter(path)
        self.writer = w
        self.size_bytes = 0
        self.start_t_s = t_s
        self.paths.append(path)
        self.recorder.counters.files += 1
        _log.info("recording %s to %s", self.name, path)
        return w

    def close(self) -> None:
        w, self.writer = self.writer, None
        if w is not None:
            w.close()


class LinkRecorder:
    """See the module docstring. ``tap`` and ``tap_feed`` are thread-safe and never block."""

    def __init__(
        self,
        folder: Path,
        *,
        config: RecordConfig | None = None,
        max_queue: int | None = None,
        on_failure: Callable[[str], None] | None = None,
    ) -> None:
        self.config = config or RecordConfig()
        check_folder(folder, self.config)
        self.folder = folder
        self.counters = RecorderCounters()
        self.failures: list[str] = []
        self._on_failure = on_failure
        try:
            self._loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            self._loop = None
        size = self.config.max_queue if max_queue is None else max_queue
        self._queue: queue.Queue[_Item | None] = queue.Queue(maxsize=size)
        self._streams: dict[str, _Stream] = {}
        self._carry: dict[str, bytearray] = {}
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    @property
    def files(self) -> dict[str, Path]:
        """Link or feed -> its current (last) file, for the streams seen so far."""
        return {name: s.paths[-1] for name, s in list(self._streams.items()) if s.paths}

    @property
    def all_files(self) -> dict[str, list[Path]]:
        """Link or feed -> every file written, in order."""
        return {name: list(s.paths) for name, s in list(self._streams.items())}

    def tap(self, link: str, data: bytes, t_s: float) -> None:
        """The hub's ``raw_tap``: queue one chunk (drop-and-count when the queue is full)."""
        self._put((link, None, bytes(data), t_s, False))

    def tap_feed(
        self, feed: str, kind: CaptureKind, data: bytes, t_s: float, new_connection: bool
    ) -> None:
        """The surveillance service's ``raw_tap``: one chunk of an ADS-B feed, as received."""
        self._put((feed, kind, bytes(data), t_s, new_connection))

    def _put(self, item: _Item) -> None:
        if self._closed:
            return
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.counters.dropped_chunks += 1
            if self.counters.dropped_chunks in (1, 100, 10_000):
                _log.warning("recorder queue full: %d chunks dropped", self.counters.dropped_chunks)

    def close(self, timeout_s: float = 10.0) -> None:
        """Write everything queued, flush and close every file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            _log.error("recorder did not finish within %.1f s", timeout_s)
        c = self.counters
        _log.info(
            "recorded %d files (%d rotations), %d packets, %d feed chunks; %d dropped, "
            "%d write errors",
            c.files,
            c.rotations,
            c.packets,
            c.feed_chunks,
            c.dropped_chunks + c.dropped_after_failure,
            c.write_errors,
        )

    def __enter__(self) -> LinkRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- writer thread -----------------------------------------------------------------------
    def _stream(self, name: str, kind: CaptureKind | None) -> _Stream:
        s = self._streams.get(name)
        if s is None:
            suffix = ".tlog" if kind is None else kind.extension
            s = self._streams[name] = _Stream(self, name, suffix, tlog=kind is None)
        return s

    def _write_link(self, stream: _Stream, data: bytes, t_s: float) -> None:
        c = self.counters
        link = stream.name
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
        for p in packets:
            stream.write(t_s, p)
            c.packets += 1

    def _write(self, item: _Item) -> None:
        name, kind, data, t_s, new_connection = item
        stream = self._stream(name, kind)
        if stream.failed:
            self.counters.dropped_after_failure += 1
            return
        try:
            if kind is None:
                self._write_link(stream, data, t_s)
            else:
                stream.write(t_s, data, new_connection=new_connection)
                self.counters.feed_chunks += 1
        except Exception as exc:  # disk full, folder gone (OSError), or a bug: never raised
            self._fail(stream, exc)

    def _fail(self, stream: _Stream, exc: Exception) -> None:
        stream.failed = True
        self.counters.write_errors += 1
        with contextlib.suppress(Exception):
            stream.close()
        what = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        where = getattr(exc, "filename", None)
        text = (
            f"recording of {stream.name} stopped: {what}"
            f"{f' ({where})' if where else ''}; the service carries on"
        )
        _log.error("%s", text, exc_info=not isinstance(exc, OSError))
        self.failures.append(text)
        if self._on_failure is not None and len(self.failures) == 1:
            if self._loop is None:
                self._on_failure(text)
            else:  # the service's event loop owns what on_failure touches
                with contextlib.suppress(RuntimeError):  # that loop is already closed
                    self._loop.call_soon_threadsafe(self._on_failure, text)

    def _run(self) -> None:
        try:
            while True:
                item = self._queue.get()
                if item is None:  # close()
                    return
                self._write(item)
        finally:
            for s in self._streams.values():
                try:
                    s.close()
                except OSError as exc:
                    self.counters.write_errors += 1
                    _log.error("recorder: cannot close %s: %s", s.name, exc)
