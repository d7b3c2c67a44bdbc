"""A bounded stop of the runtime (``serve``, ``run``, ``demo`` and ``eval`` alike, see
:meth:`gcs_utm.app.wiring.Runtime.close`): every step of the shutdown has a time limit, and a
step that overruns it is logged by name and left behind, so an instance that must stop does
stop. The steps, in order (:func:`closing_steps`): let the USM's work in progress finish
(within :data:`DRAIN_BUDGET_S`; a fenced member skips it), close the USM, the links, the
recorder, the store.

A fenced cluster member (its region may be another instance's by now) has a short budget:
its links close and it exits with code 3 within :data:`FENCED_BUDGET_S`; a plain stop
(SIGTERM) has :data:`STOP_BUDGET_S`, enough for the store writer to commit what is queued or
spill it to the journal. When service tasks do not end after being cancelled (an awaited
step that never completes), the rest of the stop still runs, bounded, and the process
exits at once (``os._exit``): a task that ignores its cancellation would otherwise keep the
event loop, and with it the process, alive for ever.
"""

from __future__ import annotations

import asyncio
import logging
import os
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Protocol

_log = logging.getLogger(__name__)

FENCED_BUDGET_S = 3.0
STOP_BUDGET_S = 40.0
# the share of the budget the service tasks get to end after their cancellation
TASKS_SHARE = 0.4
# how long a plain stop waits for the USM's uploads in progress before cancelling them
DRAIN_BUDGET_S = 10.0


class _Usm(Protocol):
    async def drain(self) -> None: ...

    async def close(self) -> None: ...


class _Hub(Protocol):
    async def close(self) -> None: ...


class _Closeable(Protocol):
    def close(self) -> None: ...


class Parts(Protocol):
    """What a stop closes of a runtime (:class:`gcs_utm.app.wiring.Runtime`)."""

    @property
    def usm(self) -> _Usm: ...

    @property
    def hub(self) -> _Hub: ...


class Stopping:
    """The time left for a stop; ``fenced``: the short budget of a fenced member."""

    def __init__(self, *, fenced: bool) -> None:
        self.fenced = fenced
        self.budget_s = FENCED_BUDGET_S if fenced else STOP_BUDGET_S
        self._end = time.monotonic() + self.budget_s
        self.overrun: list[str] = []

    def left_s(self) -> float:
        return max(0.05, self._end - time.monotonic())

    async def step(self, what: str, aw: Awaitable[object]) -> None:
        """Await ``aw`` within the time left; on overrun, log ``what`` and go on."""
        try:
            await asyncio.wait_for(aw, self.left_s())
        except TimeoutError:
            self.overrun.append(what)
            _log.error("stop: %s did not finish in time; going on without it", what)

    async def cancel(self, tasks: Sequence[asyncio.Task[object]]) -> list[str]:
        """Cancel ``tasks`` and wait for them (a share of the budget); the names of those
        still running then, each logged."""
        for t in tasks:
            t.cancel()
        if not tasks:
            return []
        _done, pending = await asyncio.wait(tasks, timeout=self.left_s() * TASKS_SHARE)
        stuck = sorted(t.get_name() for t in pending)
        for name in stuck:
            self.overrun.append(f"task {name}")
            _log.error("stop: task %s did not end after its cancellation", name)
        return stuck

    def exit_now(self, code: int, line: str) -> None:
        """Print the stop line and end the process with ``code`` without waiting for the
        tasks left behind."""
        print(line, file=sys.stderr, flush=True)
        logging.shutdown()
        sys.stdout.flush()
        os._exit(code)


async def run_steps(
    stopping: Stopping,
    steps: Sequence[tuple[str, Callable[[], object]]],
    *,
    threads: bool = True,
) -> None:
    """Each ``(name, fn)``: a coroutine function awaited, or a blocking function run on a
    thread, within the time left. ``threads`` False runs a blocking one inline: a fast-time
    loop (:class:`gcs_utm.clock.FastTimeLoop`) does not wait for threads, so their time limit
    would run out at once."""
    for what, fn in steps:
        if asyncio.iscoroutinefunction(fn):
            await stopping.step(what, fn())
        elif threads:
            await stopping.step(what, asyncio.to_thread(fn))
        else:
            fn()


def closing_steps(
    rt: Parts, store: _Closeable, recorder: _Closeable | None, stopping: Stopping
) -> list[tuple[str, Callable[[], object]]]:
    """The steps of a stop, in order (each bounded by :func:`run_steps`).

    A plain stop first lets the USM's work in progress (uploads, hazard forwarding) finish,
    within :data:`DRAIN_BUDGET_S`: an upload cut in the middle would leave a vehicle and the
    store disagreeing about its mission. A fenced member does not: its region may be another
    instance's by now, so it sends nothing more."""
    steps: list[tuple[str, Callable[[], object]]] = []
    if not stopping.fenced:

        async def drain() -> None:
            await _drain(rt.usm)

        steps.append(("usm.drain (work in progress)", drain))
    steps += [("usm.close", rt.usm.close), ("links (hub.close)", rt.hub.close)]
    if recorder is not None:
        steps.append(("recorder.close", recorder.close))
    steps.append(("store.close", store.close))
    return steps


async def _drain(usm: _Usm) -> None:
    try:
        await asyncio.wait_for(usm.drain(), DRAIN_BUDGET_S)
    except TimeoutError:
        _log.warning("stop: USM work still running after %.0f s; cancelling it", DRAIN_BUDGET_S)


__all__ = [
    "DRAIN_BUDGET_S",
    "FENCED_BUDGET_S",
    "STOP_BUDGET_S",
    "Parts",
    "Stopping",
    "closing_steps",
    "run_steps",
]
