"""tlog adapter: read, replay and record ``.tlog`` files (8-byte big-endian microsecond UNIX
timestamp + one MAVLink packet per record)."""

from adapters.tlog.reader import TlogCounters, TlogReader, TlogRecord, scan_records
from adapters.tlog.replay import ReplayStats, iter_messages, replay
from adapters.tlog.writer import TlogWriter, TlogWriterClosedError

__all__ = [
    "ReplayStats",
    "TlogCounters",
    "TlogReader",
    "TlogRecord",
    "TlogWriter",
    "TlogWriterClosedError",
    "iter_messages",
    "replay",
    "scan_records",
]
