"""Errors of the ADS-B adapter. Details are attributes; decoders catch these per record and
count them, so they never escape a read loop."""

from __future__ import annotations


class AdsbError(ValueError):
    """Base class of ADS-B decoding errors."""


class SbsFormatError(AdsbError):
    """An SBS-1 line that is not a well-formed ``MSG`` record. ``field`` names the bad field."""

    def __init__(self, line: str, field: str, reason: str) -> None:
        super().__init__(f"SBS line: {field}: {reason}: {line[:80]!r}")
        self.line = line
        self.field = field
        self.reason = reason


class ModeSFrameError(AdsbError):
    """A Mode-S frame that cannot be decoded (bad hex, bad length, unknown DF)."""

    def __init__(self, frame: str, reason: str) -> None:
        super().__init__(f"Mode-S frame {frame[:40]!r}: {reason}")
        self.frame = frame
        self.reason = reason
