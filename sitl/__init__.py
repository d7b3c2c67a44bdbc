"""PX4-like (and ArduPilot-like) simulated vehicles that speak only MAVLink over UDP/TCP.

Independent of `gcs_utm` and `adapters` by design: it is the other end of every test.
See docs/sitl.md for the wire behaviour, the fleet file format and how to run it.
"""

from sitl.fleet import Fleet, run_fleet
from sitl.mission import RawItem
from sitl.spec import (
    DEFAULT_FAULT_VALUE,
    DEFAULT_STREAM_RATES_HZ,
    FaultKind,
    FaultSpec,
    Limits,
    MissionItemSpec,
    SimTime,
    VehicleSpec,
)
from sitl.vehicle import Vehicle, mission_items_from_specs

__all__ = [
    "DEFAULT_FAULT_VALUE",
    "DEFAULT_STREAM_RATES_HZ",
    "FaultKind",
    "FaultSpec",
    "Fleet",
    "Limits",
    "MissionItemSpec",
    "RawItem",
    "SimTime",
    "Vehicle",
    "VehicleSpec",
    "mission_items_from_specs",
    "run_fleet",
]
