"""What ``gcs-utm replay`` reads and in what order: tlogs, ADS-B receiver captures and recorded
folders, merged by time into one replay of the service (:mod:`gcs_utm.app.replay`).

Inputs (:func:`discover`), any number of them:

- ``FILE.tlog``: MAVLink records (8-byte big-endian microsecond time + packet);
- ``FILE.sbs`` (SBS-1 text), ``FILE.bin``/``FILE.beast`` (Beast binary), ``FILE.avr`` (AVR
  text): one receiver feed; timed by its ``.times`` sidecar when there is one, else by its
  content (:mod:`adapters.adsb.capture`);
- a folder written by ``serve``/``run --record DIR``: every ``.tlog`` in it, and every feed's
  capture pieces (rotated files ``<feed>-<UTC start>[-n].<ext>``, grouped by feed and put in
  the order of their first recorded time), each feed decoded by one decoder across its
  pieces, as the live feed was.

Every tlog record and every decoded ADS-B measurement is an event at its record (receipt)
time; the events of all inputs are merged by time (ties: in input order) and handed to the
replay at their record times, paced at real speed, a factor, or as fast as possible (fast
time). Captures without a sidecar
whose content has only receiver-relative times (Beast, AVR ``@`` MLAT counters) start at
``adsb_start_t_s``: by default the first record of the tlogs replayed with them, else the
capture file's modification time.
"""

from __future__ import annotations

import heapq
import re
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adapters.adsb import ModeSDecoder, SbsDecoder
from adapters.adsb.capture import (
    TIMES_SUFFIX,
    CaptureDecoder,
    CaptureError,
    CaptureKind,
    capture_kind,
    iter_capture,
    times_path,
)
from adapters.adsb.config import AdsbConfig
from adapters.tlog import TlogCounters, TlogReader
from gcs_utm.app.replay import ReplayConfig, ReplayEvent, replay_blocking
from gcs_utm.app.replay_report import replay_report
from gcs_utm.model import Measurement

_PROGRESS_EVERY = 256  # events between progress-bar updates (rendering is not free)
_PIECE = re.compile(r"^(?P<feed>.+)-\d{8}T\d{6}Z(?:-\d+)?$")  # the recorder's file names


class ReplayError(ValueError):
    """A replay that cannot produce a report (missing file, no valid record)."""

    def __init__(self, path: Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


@dataclass(frozen=True, slots=True)
class Feed:
    """One receiver feed: its capture pieces in replay order."""

    name: str
    kind: CaptureKind
    pieces: tuple[Path, ...]


@dataclass(frozen=True, slots=True)
class Inputs:
    tlogs: tuple[Path, ...]
    feeds: tuple[Feed, ...]

    @property
    def files(self) -> list[Path]:
        return [*self.tlogs, *(p for f in self.feeds for p in f.pieces)]

    def total_bytes(self) -> int:
        return sum(p.stat().st_size for p in self.files)


def _first_time(piece: Path) -> float:
    """First recorded time of a capture piece (its sidecar), inf when unknown."""
    side = times_path(piece)
    try:
        with side.open(encoding="ascii", errors="replace") as f:
            first = f.readline().split()
        return int(first[0]) / 1e6
    except (OSError, IndexError, ValueError):
        return float("inf")


def _folder(path: Path) -> tuple[list[Path], list[Feed]]:
    tlogs = sorted(path.glob("*.tlog"))
    groups: dict[tuple[str, CaptureKind], list[Path]] = {}
    for p in sorted(path.iterdir()):
        kind = capture_kind(p)
        if kind is None or p.name.endswith(TIMES_SUFFIX) or not p.is_file():
            continue
        m = _PIECE.match(p.stem)
        groups.setdefault((m.group("feed") if m else p.stem, kind), []).append(p)
    feeds = [
        Feed(name, kind, tuple(sorted(pieces, key=lambda q: (_first_time(q), q.name))))
        for (name, kind), pieces in sorted(groups.items(), key=lambda kv: kv[0][0])
    ]
    if not tlogs and not feeds:
        raise ReplayError(
            path, "is a directory without any .tlog or ADS-B capture (.sbs, .avr, .bin)"
        )
    return tlogs, feeds


def discover(paths: Sequence[Path]) -> Inputs:
    """The tlogs and feeds of ``paths`` (files and recorded folders). Raises
    :class:`ReplayError` naming the first path that is missing or of an unknown kind."""
    tlogs: list[Path] = []
    feeds: list[Feed] = []
    for path in paths:
        if path.is_dir():
            t, f = _folder(path)
            tlogs += t
            feeds += f
            continue
        if not path.is_file():
            raise ReplayError(path, "no such file")
        kind = capture_kind(path)
        if kind is not None:
            feeds.append(Feed(path.stem, kind, (path,)))
        elif path.suffix.lower() == ".tlog" or (not feeds and not tlogs and len(paths) == 1):
            tlogs.append(path)  # a lone file of another name is tried as a tlog
        else:
            raise ReplayError(
                path, "unknown kind: expected .tlog, .sbs, .avr, .bin or a recorded folder"
            )
    return Inputs(tuple(tlogs), tuple(feeds))


def first_record_t_s(path: Path) -> float | None:
    """Time of the first valid record of the tlog ``path`` (None when it has none)."""
    for rec in TlogReader(path):
        return rec.t_s
    return None


def first_t_s(inputs: Inputs) -> float | None:
    """The earliest first time of the tlogs (else of the timed captures) of ``inputs``."""
    times = [t for t in (first_record_t_s(p) for p in inputs.tlogs) if t is not None]
    if not times:
        times = [t for f in inputs.feeds for t in map(_first_time, f.pieces) if t != float("inf")]
    return min(times) if times else None


# ---- events --------------------------------------------------------------------------------

_Event = tuple[float, int, bytes | Measurement]  # (t_s, input index, packet | measurement)


def _tlog_events(path: Path, index: int, counters: TlogCounters) -> Iterator[_Event]:
    reader = TlogReader(path)
    try:
        for rec in reader:
            yield rec.t_s, index, rec.packet
    finally:
        for name, value in reader.counters.as_dict().items():
            setattr(counters, name, getattr(counters, name) + value)


def _decoder(feed: Feed, config: AdsbConfig) -> CaptureDecoder:
    link = f"replay:{feed.name}"
    if feed.kind is CaptureKind.SBS:
        dec: SbsDecoder | ModeSDecoder = SbsDecoder(
            use_generated_time=config.sbs_times_are_utc,
            velocity_max_age_s=config.velocity_max_age_s,
            link=link,
            max_aircraft=config.max_aircraft,
            aircraft_idle_s=config.aircraft_idle_s,
        )
    else:
        dec = ModeSDecoder.from_config(config, link=link)
    return CaptureDecoder(feed.kind, dec)


def _feed_events(
    feed: Feed, index: int, decoder: CaptureDecoder, start_t_s: float
) -> Iterator[_Event]:
    for t_s, m in iter_capture(feed.pieces, decoder, start_t_s=start_t_s):
        yield t_s, index, m


def feed_counts(feed: Feed, decoder: CaptureDecoder) -> dict[str, int]:
    """What one replayed feed gave: frames, positions, rejects, as a live feed counts them,
    plus the decoder's and the capture reader's detail."""
    dec = decoder.decoder
    c = dec.counters
    out = {**decoder.counters.as_dict(), **c.as_dict()}
    rejects = c.corrupt + c.out_of_range
    if isinstance(dec, ModeSDecoder) and feed.kind is CaptureKind.BEAST:
        b = dec.beast_counters
        rejects += b.truncated + b.bad_type
        out["beast_truncated"] = b.truncated
        out["beast_bad_type"] = b.bad_type
    out["rejects"] = rejects
    return out


# ---- running it ----------------------------------------------------------------------------


@dataclass(slots=True)
class _Seen:
    """What went by: records (tlog), bytes, the first and last record times."""

    records: int = 0
    done_bytes: int = 0
    first_t_s: float | None = None
    last_t_s: float | None = None
    decoders: list[CaptureDecoder] = field(default_factory=list)

    def total_bytes(self) -> int:
        return self.done_bytes + sum(d.counters.bytes for d in self.decoders)


def _events(streams: list[Iterator[_Event]], seen: _Seen) -> Iterator[ReplayEvent]:
    for t_s, _, item in heapq.merge(*streams, key=lambda e: (e[0], e[1])):
        if seen.first_t_s is None:
            seen.first_t_s = t_s
        seen.last_t_s = t_s
        if isinstance(item, bytes):
            seen.records += 1
            seen.done_bytes += 8 + len(item)
        yield t_s, item


def replay_inputs(
    inputs: Inputs,
    *,
    speed: float | None = None,
    config: ReplayConfig | None = None,
    on_progress: Callable[[int], None] | None = None,
    adsb: AdsbConfig | None = None,
    adsb_start_t_s: float | None = None,
) -> dict[str, Any]:
    """Replay every input, merged by time, and return the report (see the module doc); runs
    an event loop of its own. Raises :class:`ReplayError` when nothing in them is valid or a
    capture cannot be read."""
    first = inputs.files[0]
    conf = config or ReplayConfig(link=f"tlog:{first.name}")
    adsb_config = adsb or AdsbConfig()
    start = adsb_start_t_s
    if start is None and inputs.feeds:
        tlog_t0 = [t for t in map(first_record_t_s, inputs.tlogs) if t is not None]
        start = min(tlog_t0) if tlog_t0 else inputs.feeds[0].pieces[0].stat().st_mtime
    tlog_counters = TlogCounters()
    seen = _Seen(decoders=[_decoder(f, adsb_config) for f in inputs.feeds])
    streams: list[Iterator[_Event]] = [
        _tlog_events(p, i, tlog_counters) for i, p in enumerate(inputs.tlogs)
    ]
    streams += [
        _feed_events(f, len(inputs.tlogs) + i, d, start or 0.0)
        for i, (f, d) in enumerate(zip(inputs.feeds, seen.decoders, strict=True))
    ]

    def progress(n: int) -> None:
        if on_progress is not None and n % _PROGRESS_EVERY == 0:
            on_progress(seen.total_bytes())

    wall0 = time.monotonic()
    try:
        rt = replay_blocking(conf, _events(streams, seen), speed=speed, on_event=progress)
    except CaptureError as exc:
        raise ReplayError(exc.path, exc.message) from exc
    except OSError as exc:
        raise ReplayError(Path(exc.filename or first), f"cannot read: {exc.strerror}") from exc
    if rt is None:
        raise ReplayError(first, _nothing_valid(inputs, tlog_counters))
    described = [{"path": str(p), "kind": "tlog"} for p in inputs.tlogs]
    described += [
        {"path": str(p), "kind": f.kind.value, "feed": f.name}
        for f in inputs.feeds
        for p in f.pieces
    ]
    return replay_report(
        rt,
        path=first,
        records=seen.records,
        span=(seen.first_t_s, seen.last_t_s),
        counters=tlog_counters,
        wall_s=time.monotonic() - wall0,
        inputs=described,
        adsb_feeds={
            f.name: feed_counts(f, d) for f, d in zip(inputs.feeds, seen.decoders, strict=True)
        },
    )


def _nothing_valid(inputs: Inputs, c: TlogCounters) -> str:
    if inputs.feeds and not inputs.tlogs:
        return "no ADS-B position in the capture (nothing to track)"
    return (
        f"no valid tlog record ({c.skipped_bytes} bytes skipped, "
        f"{c.corrupt_chunks} corrupt chunks): not a .tlog file?"
    )
