"""Clocks injected everywhere a time is needed: real time, simulated fast time, replay time.

Core functions never read a clock; services ask the injected :class:`Clock` and pass ``t_s``
(POSIX seconds, UTC) down. ``sleep`` waits *clock* seconds, so a service written against a
clock runs unchanged at any speed-up.
"""

from __future__ import annotations

import asyncio
import time
from typing import Protocol


class Clock(Protocol):
    @property
    def speed(self) -> float: ...

    def now_s(self) -> float:
        """Current time in POSIX seconds (UTC) on this clock."""
        ...

    async def sleep(self, duration_s: float) -> None:
        """Wait ``duration_s`` seconds of this clock's time."""
        ...


class RealClock:
    """Wall-clock time."""

    @property
    def speed(self) -> float:
        return 1.0

    def now_s(self) -> float:
        return time.time()

    async def sleep(self, duration_s: float) -> None:
        await asyncio.sleep(max(0.0, duration_s))


class ScaledClock:
    """Simulated time running ``speed`` times faster than the monotonic clock, starting at
    ``start_utc_s`` (default: now). The same formula as ``sitl.SimTime``, so the vehicles and
    the ground service agree when built with the same start, speed and monotonic anchor
    (``start_mono_s``: pass one clock's anchor to the other; at a speed-up of k, anchors taken
    d seconds apart put the clocks k*d simulated seconds apart)."""

    def __init__(
        self,
        speed: float = 1.0,
        start_utc_s: float | None = None,
        *,
        start_mono_s: float | None = None,
    ) -> None:
        if not speed > 0.0:
            raise ValueError(f"speed must be positive, got {speed}")
        self._speed = speed
        self._start_utc_s = time.time() if start_utc_s is None else start_utc_s
        self._start_mono_s = time.monotonic() if start_mono_s is None else start_mono_s

    @property
    def speed(self) -> float:
        return self._speed

    @property
    def start_utc_s(self) -> float:
        return self._start_utc_s

    @property
    def start_mono_s(self) -> float:
        return self._start_mono_s

    def now_s(self) -> float:
        return self._start_utc_s + (time.monotonic() - self._start_mono_s) * self._speed

    async def sleep(self, duration_s: float) -> None:
        await asyncio.sleep(max(0.0, duration_s) / self._speed)


class ManualClock:
    """A clock that moves only when told to: for tests and as-fast-as-possible replay.
    ``sleep`` advances the time and yields once to the loop."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._t_s = start_s

    @property
    def speed(self) -> float:
        return float("inf")

    def now_s(self) -> float:
        return self._t_s

    def set(self, t_s: float) -> None:
        if t_s < self._t_s:
            raise ValueError(f"a clock never goes back: {t_s} < {self._t_s}")
        self._t_s = t_s

    def advance(self, duration_s: float) -> None:
        self.set(self._t_s + max(0.0, duration_s))

    async def sleep(self, duration_s: float) -> None:
        self.advance(duration_s)
        await asyncio.sleep(0)
