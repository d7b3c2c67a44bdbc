"""Many vehicles on one asyncio loop, driven by one ticker task.

The ticker wakes every TICK_REAL_S of wall-clock time (shorter at speed-up, bounded below) and
advances every vehicle to the current simulated time; each vehicle integrates in fixed
simulated steps (vehicle.PHYSICS_DT_S), so the physics is the same at any speed.
Simulated time is `SimTime.elapsed_s()` minus its value when the fleet started.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence
from types import TracebackType

from sitl.spec import SimClock, VehicleSpec
from sitl.vehicle import PHYSICS_DT_S, Vehicle

_log = logging.getLogger(__name__)

MIN_TICK_REAL_S = 0.01  # at most 100 wake-ups per second, whatever the speed


class Fleet:
    """`async with Fleet(specs, sim_time) as fleet:` binds all sockets and runs the vehicles."""

    def __init__(self, specs: Sequence[VehicleSpec], sim_time: SimClock) -> None:
        ids = [s.system_id for s in specs]
        if len(set(ids)) != len(ids):
            raise ValueError(f"Fleet: duplicate system ids {sorted(ids)}")
        self.specs = tuple(specs)
        self.sim_time = sim_time
        self.vehicles: list[Vehicle] = []
        self._task: asyncio.Task[None] | None = None
        self._t0 = 0.0
        self.ticks = 0

    @property
    def t_s(self) -> float:
        """Simulated seconds since the fleet started."""
        return self.sim_time.elapsed_s() - self._t0

    def vehicle(self, sys_id: int) -> Vehicle:
        for v in self.vehicles:
            if v.sys_id == sys_id:
                return v
        raise KeyError(sys_id)

    async def start(self) -> None:
        self._t0 = self.sim_time.elapsed_s()
        self.vehicles = [Vehicle(s, self.sim_time, t0_elapsed_s=self._t0) for s in self.specs]
        try:
            for v in self.vehicles:
                await v.start()
        except BaseException:
            await self.stop()
            raise
        for v in self.vehicles:
            v.advance(0.0)
        self._task = asyncio.create_task(self._run(), name="sitl-fleet-ticker")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        for v in self.vehicles:
            await v.stop()

    async def __aenter__(self) -> Fleet:
        await self.start()
        return self

    async def __aexit__(
        self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.stop()

    async def _run(self) -> None:
        period = max(MIN_TICK_REAL_S, PHYSICS_DT_S / self.sim_time.speed)
        while True:
            t = self.t_s
            for v in self.vehicles:
                try:
                    v.advance(t)
                except Exception:  # one broken vehicle must not stop the others
                    v.counters["handler_errors"] += 1
                    _log.exception("sitl vehicle %d: tick failed", v.sys_id)
            self.ticks += 1
            await asyncio.sleep(period)


async def run_fleet(specs: Sequence[VehicleSpec], sim_time: SimClock, stop: asyncio.Event) -> None:
    """Run the fleet until `stop` is set."""
    async with Fleet(specs, sim_time) as fleet:
        _log.info(
            "sitl: %d vehicle(s) running, speed %.1f: %s",
            len(fleet.vehicles),
            sim_time.speed,
            ", ".join(
                f"sysid {v.sys_id} udp {v.local_port} tcp {v.tcp_port}" for v in fleet.vehicles
            ),
        )
        await stop.wait()
