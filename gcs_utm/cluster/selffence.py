"""Self-fencing of what reaches a vehicle: no command and no plan upload without a live lease.

The store fences the rows of a region (:mod:`gcs_utm.cluster.fence`) and the ownership
policy drops threats and decisions while this instance may not act
(:mod:`gcs_utm.cluster.policy`); a command or a mission upload goes to a vehicle, not the
store, so it is checked here, just before it is sent: ``may_act`` is a local check of the
lease deadlines on the monotonic clock (no I/O). A refused one fails like a vehicle that did
not answer (``ok`` False, the reason in ``error``), so the USM audits it as any failed
command and EM hears a failed outcome.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gcs_utm.model import Autopilot, Command, FlightPlan, SysId
from gcs_utm.services.recommendations import CommandOutcome, UploadOutcome, VehiclePort

REFUSED = "not sent: this instance's region lease has expired (self-fenced)"


@dataclass(frozen=True, slots=True)
class Refused:
    """A command or upload this instance was not allowed to send."""

    ok: bool = False
    verified: bool = False
    error: str = REFUSED


class FencedVehicles:
    """A :class:`VehiclePort` that sends only while ``may_act()``; ``refused`` counts the
    rest."""

    def __init__(self, vehicles: VehiclePort, may_act: Callable[[], bool]) -> None:
        self._vehicles = vehicles
        self._may_act = may_act
        self.refused = 0
        # reading a vehicle's mission (how its operation is filed) changes nothing: passed on
        download = getattr(vehicles, "download_mission", None)
        if download is not None:
            self.download_mission = download

    async def upload_plan(
        self,
        sys_id: SysId,
        plan: FlightPlan,
        *,
        autopilot: Autopilot | None = None,
        deadline_t_s: float | None = None,
        start_index: int = 0,
        climb_rate_mps: float | None = None,
        descent_rate_mps: float | None = None,
        min_speed_mps: float = 0.0,
    ) -> UploadOutcome:
        if not self._may_act():
            self.refused += 1
            return Refused()
        return await self._vehicles.upload_plan(
            sys_id,
            plan,
            autopilot=autopilot,
            deadline_t_s=deadline_t_s,
            start_index=start_index,
            climb_rate_mps=climb_rate_mps,
            descent_rate_mps=descent_rate_mps,
            min_speed_mps=min_speed_mps,
        )

    async def send_command(self, sys_id: SysId, command: Command) -> CommandOutcome:
        if not self._may_act():
            self.refused += 1
            return Refused()
        return await self._vehicles.send_command(sys_id, command)


__all__ = ["REFUSED", "FencedVehicles", "Refused"]
