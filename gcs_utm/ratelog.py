"""Rate-limited logging: one line per cause per interval, with the count of what was held back.

A sender can make the same complaint thousands of times a second (a spoofed stream of frames
whose ``time_boot_ms`` goes backwards, a dead socket written to on every heartbeat). Logging
each one floods the log and costs more than the frame; logging none hides the fault. A
:class:`RateLimitedLog` writes the first occurrence of each *cause* at once, counts the repeats
for ``interval_s`` and writes the next one with that count ("... (1,234 more since the last
line)"); :meth:`RateLimitedLog.flush` writes the counts still held (call it periodically, or
at shutdown, so a burst that stopped is still reported).

A cause is a short string naming the complaint (``"reboot"``, ``"send:tcp:host:5760"``). At
most ``max_causes`` are remembered; beyond that the oldest is forgotten (its held count is
written first), so causes built from untrusted input cannot grow memory.

Time comes from ``now`` (monotonic seconds by default; tests inject a clock).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(slots=True)
class _Cause:
    last_t_s: float
    held: int = 0
    level: int = logging.WARNING
    msg: str = ""
    args: tuple[object, ...] = ()


class RateLimitedLog:
    """See the module docstring. ``held_total`` counts every line not written."""

    def __init__(
        self,
        logger: logging.Logger,
        interval_s: float = 10.0,
        *,
        now: Callable[[], float] = time.monotonic,
        max_causes: int = 256,
    ) -> None:
        if interval_s < 0.0:
            raise ValueError(f"interval_s must be >= 0, got {interval_s}")
        if max_causes < 1:
            raise ValueError(f"max_causes must be >= 1, got {max_causes}")
        self.logger = logger
        self.interval_s = interval_s
        self.now = now
        self.max_causes = max_causes
        self.held_total = 0
        self._causes: dict[str, _Cause] = {}

    def log(
        self,
        level: int,
        cause: str,
        msg: str,
        *args: object,
        exc_info: BaseException | None = None,
    ) -> bool:
        """Log ``msg % args`` for ``cause`` unless it was logged less than ``interval_s``
        ago (then count it). Returns True when a line was written. ``exc_info``: its
        traceback goes with a line that is written (never with the held repeats)."""
        t = self.now()
        c = self._causes.get(cause)
        if c is not None and t - c.last_t_s < self.interval_s:
            c.held += 1
            c.level, c.msg, c.args = level, msg, args
            self.held_total += 1
            return False
        held = 0
        if c is None:
            if len(self._causes) >= self.max_causes:
                self._forget_oldest()
            self._causes[cause] = _Cause(last_t_s=t)
        else:
            held, c.held, c.last_t_s = c.held, 0, t
        self._write(level, msg, args, held, exc_info=exc_info)
        return True

    def warning(self, cause: str, msg: str, *args: object) -> bool:
        return self.log(logging.WARNING, cause, msg, *args)

    def info(self, cause: str, msg: str, *args: object) -> bool:
        return self.log(logging.INFO, cause, msg, *args)

    def flush(self) -> int:
        """Write one line for every cause with held repeats whose interval has passed (the
        last held message, with the count); returns how many lines were written."""
        t = self.now()
        lines = 0
        for c in self._causes.values():
            if c.held and t - c.last_t_s >= self.interval_s:
                self._write(c.level, c.msg, c.args, c.held - 1, last=True)
                c.held, c.last_t_s = 0, t
                lines += 1
        return lines

    def _forget_oldest(self) -> None:
        cause = min(self._causes, key=lambda k: self._causes[k].last_t_s)
        c = self._causes.pop(cause)
        if c.held:
            self._write(c.level, c.msg, c.args, c.held - 1, last=True)

    def _write(
        self,
        level: int,
        msg: str,
        args: tuple[object, ...],
        held: int,
        *,
        last: bool = False,
        exc_info: BaseException | None = None,
    ) -> None:
        if held or last:
            msg = f"{msg} ({held:,} more since the last line)"
        self.logger.log(level, msg, *args, exc_info=exc_info)
