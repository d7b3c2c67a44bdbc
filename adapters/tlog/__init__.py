"""tlog adapter: read and record ``.tlog`` files (8-byte big-endian microsecond UNIX timestamp
+ one MAVLink packet per record). Replaying them is the service's own business
(:mod:`gcs_utm.app.replay`: the packets go through the MAVLink hub as a live link's do)."""

from adapters.tlog.reader import TlogCounters, TlogReader, TlogRecord, scan_records
from adapters.tlog.writer import TlogWriter, TlogWriterClosedError

__all__ = [
    "TlogCounters",
    "TlogReader",
    "TlogRecord",
    "TlogWriter",
    "TlogWriterClosedError",
    "scan_records",
]
