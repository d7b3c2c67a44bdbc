"""Monitoring service: runs ``Monitor.cycle`` every ``period_s`` on one consistent snapshot and
hands the resulting threats to EM.

A cycle never overlaps the next: the loop awaits each cycle before sleeping for the rest of
the period; a cycle longer than the period is logged and the next one starts at once (no
catch-up burst). Cancellation stops the loop between or during awaits; the monitor's state
stays consistent because ``cycle`` itself is synchronous.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable

from gcs_utm.clock import Clock
from gcs_utm.core.monitoring import Monitor
from gcs_utm.model import AirspaceSnapshot, Threat

_log = logging.getLogger(__name__)


class MonitoringService:
    def __init__(
        self,
        monitor: Monitor,
        snapshot_provider: Callable[[float], AirspaceSnapshot],
        clock: Clock,
        on_threats: Callable[[list[Threat]], Awaitable[None]],
        period_s: float,
    ) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s must be positive, got {period_s}")
        self.monitor = monitor
        self._provider = snapshot_provider
        self._clock = clock
        self._on_threats = on_threats
        self.period_s = period_s
        self.cycles = 0

    def run_once(self, t_s: float) -> list[Threat]:
        """One cycle at ``t_s``: snapshot, detect, return the opened/updated/closed threats."""
        threats = self.monitor.cycle(self._provider(t_s))
        self.cycles += 1
        return threats

    async def run(self) -> None:
        while True:
            t0 = self._clock.now_s()
            threats = self.run_once(t0)
            if threats:
                await self._on_threats(threats)
            took = self._clock.now_s() - t0
            if took > self.period_s:
                _log.warning("monitoring cycle took %.3f s (period %.3f s)", took, self.period_s)
            await self._clock.sleep(max(0.0, self.period_s - took))
