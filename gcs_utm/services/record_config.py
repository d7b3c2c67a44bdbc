"""Settings of ``serve``/``run --record DIR`` (section ``[record]``).

Every MAVLink link is recorded as ``.tlog`` files and every ADS-B receiver feed as raw
capture files (``adapters.adsb.capture``); each stream starts a new file when the current one
would grow past ``max_file_mb`` or has covered ``max_file_s`` of record time.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class RecordConfig:
    """``serve``/``run --record DIR``: MAVLink links as tlogs, ADS-B feeds raw, rotated files."""

    max_file_mb: float = setting(
        256.0,
        "a recorded file (tlog or ADS-B capture) is closed and a new one started before it "
        "would grow past this size",
        min=0.001,
        max=1_000_000.0,
        unit="MB",
    )
    max_file_s: float = setting(
        3600.0,
        "a recorded file is closed and a new one started once it covers this much record time",
        min=1.0,
        max=7.0 * 86_400.0,
        unit="s",
    )
    min_free_mb: float = setting(
        64.0,
        "--record refuses to start when the folder's disk has less free space than this",
        min=0.0,
        max=1_000_000.0,
        unit="MB",
    )
    adsb: bool = setting(
        True, "record the [adsb] receiver feeds raw (bytes as received, with their times)"
    )
    max_queue: int = setting(
        10_000,
        "chunks waiting for the recorder thread; when full, chunks are dropped and counted "
        "(recording never slows a link down)",
        min=16,
        max=10_000_000,
    )
