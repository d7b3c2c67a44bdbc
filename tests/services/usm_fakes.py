"""Shared test doubles for the USM: a one-operation airspace and a vehicle port that records
uploads and commands (answers ok/verified as told)."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.model import (
    Autopilot,
    Command,
    FlightPlan,
    Operation,
    OperationId,
    SysId,
    VehicleKind,
    Waypoint4D,
)

OP = OperationId("UAS1")


def make_plan(version: int, t0: float) -> FlightPlan:
    return FlightPlan(
        operation_id=OP,
        version=version,
        waypoints=(
            Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0, t_s=t0),
            Waypoint4D(lat_deg=40.001, lon_deg=-3.0, alt_amsl_m=700.0, t_s=t0 + 30),
        ),
    )


def make_operation(t0: float, *, operator: str = "default") -> Operation:
    return Operation(
        id=OP,
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=make_plan(1, t0),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=5.0,
        operational_volume_m=15.0,
        operator=operator,
    )


@dataclass
class Result:
    ok: bool
    verified: bool
    error: str = ""


class FakeVehicles:
    def __init__(self, *, verified: bool = True, command_ok: bool = True) -> None:
        self.uploads: list[FlightPlan] = []
        self.start_indices: list[int] = []
        self.rates: list[tuple[float | None, float | None]] = []
        self.min_speeds: list[float] = []
        self.lands: list[bool] = []
        self.commands: list[Command] = []
        self.verified = verified
        self.command_ok = command_ok

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
    ) -> Result:
        self.uploads.append(plan)
        self.lands.append(lands)
        self.min_speeds.append(min_speed_mps)
        self.start_indices.append(start_index)
        self.rates.append((climb_rate_mps, descent_rate_mps))
        return Result(ok=True, verified=self.verified, error="" if self.verified else "mismatch")

    async def send_command(self, sys_id: SysId, command: Command) -> Result:
        self.commands.append(command)
        return Result(ok=self.command_ok, verified=True)
