"""The composition root: reads settings, builds the concrete parts, connects them, and runs them
as one ``asyncio.TaskGroup`` of named tasks.

- :mod:`.wiring`: the one builder (``build_runtime``, ``attach_frontends``,
  ``start_service_tasks``) used by both jobs;
- :mod:`.runner`: scenario runs (simulated vehicles on the same clock, at a speed-up or in
  fast time), writing the report;
- :mod:`.report`: the typed run report and its JSON;
- :mod:`.serve`: the long-running service.

Process-wide interpreter settings are the entry point's business (:func:`configure_interpreter`,
called by the CLI before it starts a loop), not the builder's.
"""

from __future__ import annotations

import sys

from .memory import retain_freed_memory
from .report import Report, build_report
from .runner import (
    FAST_TIME_EPOCH_UTC_S,
    RunOptions,
    report_path,
    run_scenario,
    run_scenario_blocking,
    vehicle_specs,
)
from .serve import serve
from .wiring import (
    FrontendOptions,
    Frontends,
    OperatorMode,
    Persistence,
    Runtime,
    apply_decision,
    attach_frontends,
    build_runtime,
    start_service_tasks,
)

GIL_SWITCH_INTERVAL_S = 0.0002
"""The event loop shares the interpreter with the store's writer thread, which holds the GIL
for ~10-15 ms when it encodes a second's tracks (1,000 tracks). With Python's default switch
interval (5 ms) the loop waits up to 5 ms at each switch; this bounds each wait (the
measurements behind the value are in docs/performance.md)."""


def configure_interpreter() -> None:
    """Process-wide settings the running service needs (see GIL_SWITCH_INTERVAL_S and
    :mod:`.memory`): called by the entry point, once, before the event loop starts."""
    if sys.getswitchinterval() > GIL_SWITCH_INTERVAL_S:
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    retain_freed_memory()  # the monitoring cycle reuses its arrays' memory (memory.py)


__all__ = [
    "FAST_TIME_EPOCH_UTC_S",
    "GIL_SWITCH_INTERVAL_S",
    "FrontendOptions",
    "Frontends",
    "OperatorMode",
    "Persistence",
    "Report",
    "RunOptions",
    "Runtime",
    "apply_decision",
    "attach_frontends",
    "build_report",
    "build_runtime",
    "configure_interpreter",
    "report_path",
    "run_scenario",
    "run_scenario_blocking",
    "serve",
    "start_service_tasks",
    "vehicle_specs",
]
