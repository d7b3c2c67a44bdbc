"""Self-fencing of what reaches a vehicle: no command, no plan upload and no traffic
information without a live lease.

The store fences the rows of a region (:mod:`gcs_utm.cluster.fence`) and the ownership
policy drops threats and decisions while this instance may not act
(:mod:`gcs_utm.cluster.policy`); a command or a mission upload goes to a vehicle, not the
store, so it is checked here, just before it is sent: ``may_act`` is a local check of the
lease deadlines on the monotonic clock (no I/O). A refused one fails like a vehicle that did
not answer (``ok`` False, the reason in ``error``), so the USM audits it as any failed
command and EM hears a failed outcome.

Traffic information (ADSB_VEHICLE, :mod:`adapters.mavlink.traffic_out`) goes to a vehicle
from its owner only: behind a MAVLink router every instance hears every vehicle and would
otherwise send each vehicle the traffic near it once per instance, the stale owner of a
stalled instance included. :class:`OwnedTraffic` shows traffic-out only the vehicles this
instance commands (their operation owned here, the lease deadline not passed) and checks
again before each frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from adapters.mavlink.traffic_out import TrafficHub
from adapters.mavlink.vehicle import VehicleInfo, VehicleState
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.model import Autopilot, Command, FlightPlan, Operation, SysId
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
        lands: bool = False,
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
            lands=lands,
        )

    async def send_command(self, sys_id: SysId, command: Command) -> CommandOutcome:
        if not self._may_act():
            self.refused += 1
            return Refused()
        return await self._vehicles.send_command(sys_id, command)


class OwnedTraffic:
    """The hub as traffic-out sees it in a cluster (a :class:`TrafficHub`): a vehicle is
    shown while ``operation_of(its sys id)`` is an operation ``policy`` owns and the policy
    may act; ``withheld`` counts the frames kept back."""

    def __init__(
        self,
        hub: TrafficHub,
        policy: OwnershipPolicy,
        operation_of: Callable[[SysId], Operation | None],
    ) -> None:
        self._hub = hub
        self._policy = policy
        self._operation_of = operation_of
        self.withheld = 0

    def _commands(self, sys_id: SysId) -> bool:
        op = self._operation_of(sys_id)
        return op is not None and self._policy.owns(op.id) and self._policy.may_act()

    def vehicles(self) -> list[VehicleInfo]:
        return [v for v in self._hub.vehicles() if self._commands(SysId(v.key.sys_id))]

    def state(self, vehicle: SysId) -> VehicleState:
        return self._hub.state(vehicle)

    def send_raw(self, vehicle: SysId, name: str, *args: object) -> None:
        if not self._commands(vehicle):  # lost between the round's start and this frame
            self.withheld += 1
            return
        self._hub.send_raw(vehicle, name, *args)


__all__ = ["REFUSED", "FencedVehicles", "OwnedTraffic", "Refused"]
