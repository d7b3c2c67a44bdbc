"""Settings of the Monitoring module (section ``[monitoring]``).

Units are in the names: metres (``_m``), seconds (``_s``), cycles (``_cycles``). Every field
is declared with :func:`gcs_utm.config.setting` so ``config/default.toml`` is generated from
this class. All defaults are usable as they are (``MonitoringConfig()``).

Invariant used by the detectors: the separation minimum applied to a pair is never less than
the sum of the two operational-volume radii (``effective_minima``).
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting

SEPARATION_MODES = ("cylinder", "sphere")


@dataclass(frozen=True, slots=True, kw_only=True)
class MonitoringConfig:
    period_s: float = setting(1.0, "monitoring cycle period", min=0.05, max=60.0, unit="s")
    separation_mode: str = setting(
        "cylinder",
        "loss-of-separation shape: 'cylinder' = horizontal AND vertical minima both violated; "
        "'sphere' = the paper's single 3D safety distance",
    )
    separation_horizontal_m: float = setting(
        50.0, "horizontal separation minimum between two UAS", min=0.0, unit="m"
    )
    separation_vertical_m: float = setting(
        15.0, "vertical separation minimum between two UAS", min=0.0, unit="m"
    )
    safety_distance_m: float = setting(
        50.0,
        "the paper's single 3D safety distance (separation_mode = 'sphere')",
        min=0.0,
        unit="m",
    )
    intruder_horizontal_m: float = setting(
        150.0,
        "horizontal minimum between a UAS and a non-cooperative intruder",
        min=0.0,
        unit="m",
    )
    intruder_vertical_m: float = setting(
        50.0, "vertical minimum between a UAS and a non-cooperative intruder", min=0.0, unit="m"
    )
    grid_dx_m: float = setting(
        400.0,
        "4D grid cell size east (enlarged automatically if a swept box is wider)",
        min=1.0,
        unit="m",
    )
    grid_dy_m: float = setting(400.0, "4D grid cell size north", min=1.0, unit="m")
    grid_dz_m: float = setting(60.0, "4D grid cell size vertical", min=1.0, unit="m")
    grid_dt_s: float = setting(
        10.0, "4D grid cell duration (rounded to whole prediction steps)", min=0.0, unit="s"
    )
    allpairs_below: int = setting(
        500,
        "use the all-pairs detector instead of the grid below this many trajectories",
        min=0,
    )
    gate_takeoff_landing: bool = setting(
        True, "do not raise conformance threats during take-off/landing near home"
    )
    gate_outside_plan_time: bool = setting(
        True,
        "do not raise conformance threats before the plan's first or after its last waypoint "
        "time (pre-departure, and the loiter/landing after the plan; a fixed wing cannot "
        "stop on its last waypoint)",
    )
    takeoff_landing_radius_m: float = setting(
        30.0,
        "horizontal radius around home (or first/last waypoint) gated as take-off/landing",
        min=0.0,
        unit="m",
    )
    takeoff_landing_height_m: float = setting(
        20.0, "height above home below which the phase gate applies", min=0.0, unit="m"
    )
    conformance_time_tolerance_s: float = setting(
        30.0,
        "conformance compares the position with the plan portion within this time of now",
        min=0.0,
        unit="s",
    )
    conformance_max_track_age_s: float = setting(
        1.5,
        "conformance is judged only from a track measured at most this long ago: a silent "
        "track's dead-reckoned position neither raises, escalates nor closes a conformance "
        "threat (past [tracking] stale_after_s the link-loss threat is raised instead)",
        min=0.0,
        unit="s",
    )
    open_cycles: int = setting(
        1, "consecutive cycles a condition must hold before a threat opens", min=1, max=100
    )
    close_cycles: int = setting(
        3,
        "consecutive fresh cycles a condition must be absent before a threat closes",
        min=1,
        max=1000,
    )
    conformance_close_margin_m: float = setting(
        2.0,
        "a conformance threat closes only when back this far inside the limit",
        min=0.0,
        unit="m",
    )
    separation_close_margin_m: float = setting(
        5.0,
        "a separation threat closes only when clear by this extra distance",
        min=0.0,
        unit="m",
    )

    def __post_init__(self) -> None:
        if self.separation_mode not in SEPARATION_MODES:
            raise ValueError(
                f"monitoring.separation_mode: expected one of {SEPARATION_MODES}, "
                f"got {self.separation_mode!r}"
            )

    @property
    def spherical(self) -> bool:
        return self.separation_mode == "sphere"

    def effective_minima(self, ov_a_m: float, ov_b_m: float) -> tuple[float, float]:
        """(horizontal_m, vertical_m) minimum for a pair with these operational volumes.

        In sphere mode both numbers are the 3D safety distance."""
        floor = ov_a_m + ov_b_m
        if self.spherical:
            s = max(self.safety_distance_m, floor)
            return s, s
        return max(self.separation_horizontal_m, floor), max(self.separation_vertical_m, floor)
