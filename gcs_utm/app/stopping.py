"""A bounded stop of ``serve``: every step of the shutdown has a time limit, and a step that
overruns it is logged by name and left behind, so an instance that must stop does stop.

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

_log = logging.getLogger(__name__)

FENCED_BUDGET_S = 3.0
STOP_BUDGET_S = 40.0
# the share of the budget the service tasks get to end after their cancellation
TASKS_SHARE = 0.4


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


async def run_steps(stopping: Stopping, steps: Sequence[tuple[str, Callable[[], object]]]) -> None:
    """Each ``(name, fn)``: a coroutine function awaited, or a blocking function run on a
    thread, within the time left."""
    for what, fn in steps:
        if asyncio.iscoroutinefunction(fn):
            await stopping.step(what, fn())
        else:
            await stopping.step(what, asyncio.to_thread(fn))


__all__ = ["FENCED_BUDGET_S", "STOP_BUDGET_S", "Stopping", "run_steps"]
