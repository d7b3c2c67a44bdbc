"""A mission point as the fixed-wing models read it, and the MAVLink commands they know
(pure; shared by :mod:`.fixed_wing_plan` and :mod:`.fixed_wing_loiter`, which import it and
never each other's types)."""

from __future__ import annotations

from typing import Protocol, Self

NAV_LOITER_TURNS = 18
NAV_LOITER_TIME = 19
NAV_LAND = 21
NAV_TAKEOFF = 22
NAV_LOITER_TO_ALT = 31
LOITER_COMMANDS = frozenset({NAV_LOITER_TURNS, NAV_LOITER_TIME, NAV_LOITER_TO_ALT})


class Point(Protocol):
    """What this module reads and writes of a mission point (vehicle_ops.NavPoint)."""

    @property
    def seq(self) -> int: ...
    @property
    def lat_deg(self) -> float: ...
    @property
    def lon_deg(self) -> float: ...
    @property
    def alt_amsl_m(self) -> float: ...
    @property
    def speed_mps(self) -> float: ...
    @property
    def explicit(self) -> bool: ...
    @property
    def command(self) -> int: ...
    @property
    def radius_m(self) -> float: ...
    @property
    def amount(self) -> float: ...
    @property
    def exit_xtrack(self) -> bool: ...
    def moved(self, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> Self: ...
    def synthetic(self) -> Self: ...
