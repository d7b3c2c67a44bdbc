"""Recording any link to a ``.tlog``: ``TlogWriter(path).write(t_s, packet)``.

Records are appended to an in-memory batch and written with one ``write`` call when the batch
holds ``batch_records`` records or is older than ``flush_interval_s`` (checked on write, by the
record times given), and on :meth:`flush`/:meth:`close`. Each record is complete in the batch,
so a crash loses at most the unflushed batch and leaves at most a truncated last record, which
:class:`~adapters.tlog.reader.TlogReader` counts and skips. Blocking file I/O: call it from a
thread or accept small writes on the loop (one ``write`` of at most a batch).
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import BinaryIO


class TlogWriterClosedError(ValueError):
    def __init__(self, path: Path) -> None:
        super().__init__(f"{path}: tlog writer is closed")
        self.path = path


class TlogWriter:
    """Append-only tlog writer; usable as a context manager."""

    def __init__(
        self,
        path: str | Path,
        *,
        append: bool = False,
        batch_records: int = 256,
        flush_interval_s: float = 1.0,
    ) -> None:
        self.path = Path(path)
        self._file: BinaryIO | None = self.path.open("ab" if append else "wb")
        self._batch = bytearray()
        self._pending = 0
        self._batch_start_t_s: float | None = None
        self._batch_records = batch_records
        self._flush_interval_s = flush_interval_s
        self.records = 0

    def write(self, t_s: float, packet: bytes) -> None:
        """Add one packet received at ``t_s`` (POSIX seconds)."""
        if self._file is None:
            raise TlogWriterClosedError(self.path)
        self._batch += round(t_s * 1e6).to_bytes(8, "big")
        self._batch += packet
        self._pending += 1
        self.records += 1
        if self._batch_start_t_s is None:
            self._batch_start_t_s = t_s
        if (
            self._pending >= self._batch_records
            or t_s - self._batch_start_t_s >= self._flush_interval_s
        ):
            self.flush()

    def flush(self) -> None:
        if self._file is None or not self._batch:
            return
        self._file.write(self._batch)
        self._file.flush()
        self._batch.clear()
        self._pending = 0
        self._batch_start_t_s = None

    def close(self) -> None:
        if self._file is None:
            return
        try:
            self.flush()
        finally:
            self._file.close()
            self._file = None

    @property
    def closed(self) -> bool:
        return self._file is None

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
