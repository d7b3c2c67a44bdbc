"""MAVLink adapter: links (UDP/TCP/serial), telemetry -> measurements, mission upload with
readback verification, commands, MAVLink 2 signing. See docs/usm.md."""

from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.endpoint import Endpoint, EndpointError, EndpointKind, parse_endpoint
from adapters.mavlink.hub import MavlinkHub, TelemetrySink
from adapters.mavlink.hub_report import HubCounters
from adapters.mavlink.mission import MissionItem, plan_to_mission_items
from adapters.mavlink.transfer import CommandResult, MavlinkError, UploadFailure, UploadResult
from adapters.mavlink.transport import LinkError
from adapters.mavlink.vehicle import VehicleInfo

__all__ = [
    "CommandResult",
    "Endpoint",
    "EndpointError",
    "EndpointKind",
    "HubCounters",
    "LinkError",
    "MavlinkConfig",
    "MavlinkError",
    "MavlinkHub",
    "MissionItem",
    "TelemetrySink",
    "UploadFailure",
    "UploadResult",
    "VehicleInfo",
    "parse_endpoint",
    "plan_to_mission_items",
]
