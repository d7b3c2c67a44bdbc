"""Clocks injected everywhere a time is needed: real time, simulated fast time, replay time.

Core functions never read a clock; services ask the injected :class:`Clock` and pass ``t_s``
(POSIX seconds, UTC) down. ``sleep`` waits *clock* seconds, so a service written against a
clock runs unchanged at any speed-up.
"""

from __future__ import annotations

import asyncio
import selectors
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


class LoopClock:
    """Simulated time read from the running event loop: ``now_s = start_utc_s + (loop.time()
    - anchor)``. On an ordinary loop this is real time; on a :class:`FastTimeLoop` it is fast
    time, and every ``asyncio.sleep``, ``call_later`` and ``wait_for`` of every part on that
    loop (UTM services, MAVLink hub, simulated vehicles) runs on the same simulated seconds.

    One object serves the ground services (:class:`Clock`) and the simulated vehicles (it has
    what ``sitl.SimClock`` asks for: ``elapsed_s``, ``real_delay_s``, ``start_utc_s``), so the
    two sides share one clock instead of two clocks built to agree. ``speed`` is 1: one
    simulated second per loop second (how fast loop seconds pass is the loop's business).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, start_utc_s: float) -> None:
        self._loop = loop
        self._start_utc_s = start_utc_s
        self._anchor_s = loop.time()

    @property
    def speed(self) -> float:
        return 1.0

    @property
    def start_utc_s(self) -> float:
        return self._start_utc_s

    def elapsed_s(self) -> float:
        """Simulated seconds since the clock was made."""
        return self._loop.time() - self._anchor_s

    def now_s(self) -> float:
        return self._start_utc_s + self.elapsed_s()

    def real_delay_s(self, sim_s: float) -> float:
        """Loop seconds that ``sim_s`` simulated seconds take (the same, at speed 1)."""
        return sim_s

    async def sleep(self, duration_s: float) -> None:
        await asyncio.sleep(max(0.0, duration_s))


class _FastTimeSelector(selectors.DefaultSelector):
    """The loop's I/O poll. Sockets are always polled without waiting; when none is ready and
    the loop would wait for its next timer, the loop's time jumps to that timer instead.
    Waiting for I/O really happens only when nothing at all is scheduled."""

    def __init__(self, loop_time: _VirtualTime) -> None:
        super().__init__()
        self._time = loop_time

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        events = super().select(0)
        if events or timeout == 0:
            return events
        if timeout is None:
            return super().select(None)
        self._time.t_s += timeout
        return []


class _VirtualTime:
    def __init__(self, start_s: float) -> None:
        self.t_s = start_s


class FastTimeLoop(asyncio.SelectorEventLoop):
    """An event loop whose time advances as fast as the computation allows (BlueSky-style
    fast time): it runs every callback that is ready and every datagram that has arrived, and
    only then jumps to the next timer. Nothing waits for the wall clock, so a run is as long
    as its computation, and its order of events does not depend on how loaded the machine is.

    Loopback sockets keep working unchanged: a datagram sent to a socket of this process is in
    the receiver's buffer when ``sendto`` returns (the kernel delivers loopback traffic in the
    sending call), so the poll before each jump sees it. A thread that posts to the loop
    (``call_soon_threadsafe``) is not waited for: fast time is for code whose timing is on the
    loop. Loop time starts at 0.
    """

    def __init__(self) -> None:
        self._virtual = _VirtualTime(0.0)
        super().__init__(_FastTimeSelector(self._virtual))

    def time(self) -> float:
        return self._virtual.t_s
