"""Settings of Tactical Deconfliction (section ``[deconfliction]``).

Units are in the names. Every field is declared with :func:`gcs_utm.config.setting` so that
``config/default.toml`` is generated from this class; ``DeconflictionConfig()`` is usable as is.
The cost and riskiness formulas these weights enter are documented in ``docs/deconfliction.md``
and in :mod:`gcs_utm.core.deconfliction.scoring`.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class DeconflictionConfig:
    # ---- charged cords (multi-UAS) ---------------------------------------------------------
    cord_dt_s: float = setting(
        2.0, "time step between the points of a charged cord", min=0.1, max=30.0, unit="s"
    )
    horizon_s: float = setting(
        600.0, "plans are deformed at most this far ahead of now", min=10.0, unit="s"
    )
    max_iterations: int = setting(
        60, "iterations of the repulsion procedure before a scenario is given up", min=1
    )
    separation_margin_fraction: float = setting(
        0.15,
        "cords are pushed until separated by the minimum times (1 + this), so that the "
        "simplified plan still holds the minimum",
        min=0.0,
        max=2.0,
    )
    climb_fraction: float = setting(
        0.6,
        "share of the vehicle's max climb rate a vertical deformation may use (the rest is "
        "left for the plan's own climbs)",
        min=0.05,
        max=1.0,
    )
    max_lateral_angle_deg: float = setting(
        30.0,
        "max angle of a lateral deformation ramp to the planned track",
        min=1.0,
        max=80.0,
        unit="deg",
    )
    max_lateral_offset_m: float = setting(
        1000.0, "largest lateral deformation of a plan", min=1.0, unit="m"
    )
    max_vertical_offset_m: float = setting(
        120.0, "largest vertical deformation of a plan", min=1.0, unit="m"
    )
    min_alt_amsl_m: float = setting(
        -500.0, "airspace floor used when an operation has no min_alt_amsl_m", unit="m"
    )
    max_alt_amsl_m: float = setting(
        10000.0, "airspace ceiling used when an operation has no max_alt_amsl_m", unit="m"
    )
    min_height_above_home_m: float = setting(
        10.0,
        "safety floor: no generated waypoint below the vehicle's home altitude plus this (its "
        "filed take-off and landing points and a landing manoeuvre's touchdown aside)",
        min=0.0,
        unit="m",
    )
    immovable_priority: int = setting(
        1000, "operations with this priority or higher are never deformed", min=1
    )
    max_speed_factor: float = setting(
        1.2,
        "a new plan may ask for up to this times the cruise speed on deformed segments; "
        "slower segments are re-timed",
        min=1.0,
        max=3.0,
    )
    delay_step_s: float = setting(5.0, "step of the delay alternative search", min=0.5, unit="s")
    max_delay_s: float = setting(120.0, "largest delay alternative", min=0.0, unit="s")
    slowdown_factors: tuple[float, ...] = setting(
        (0.8, 0.6), "speed factors tried for the speed-change alternative (fraction of plan)"
    )
    # ---- A* (single UAS) -------------------------------------------------------------------
    clearance_margin_m: float = setting(
        5.0,
        "extra clearance from geofences on top of the operation's operational-volume radius",
        min=0.0,
        unit="m",
    )
    cylinder_sides: int = setting(
        8, "sides of the circumscribed polygon approximating a cylinder", min=6, max=64
    )
    escape_distance_m: float = setting(
        20.0, "how far past the clearance an escape point is placed", min=0.0, unit="m"
    )
    # ---- cost and riskiness ----------------------------------------------------------------
    cost_distance_scale_m: float = setting(
        1000.0, "extra distance counted as one unit of cost", min=1.0, unit="m"
    )
    cost_time_scale_s: float = setting(
        120.0, "extra time counted as one unit of cost", min=1.0, unit="s"
    )
    cost_offset_scale_m: float = setting(
        1000.0,
        "farthest 3D distance of a new path from the old one counted as one unit of cost "
        "(leaving the plan costs even when it is not longer)",
        min=1.0,
        unit="m",
    )
    abandon_cost: float = setting(
        5.0, "cost added when an alternative abandons the mission (home, landing site)", min=0.0
    )
    priority_cost_weight: float = setting(
        0.5,
        "cost of moving a UAS is multiplied by 1 + this * (priority - lowest priority in the "
        "conflict): higher priority moves less",
        min=0.0,
    )
    priority_move_cost: float = setting(
        0.5,
        "cost added to any change of plan of a UAS per priority level above the lowest in the "
        "conflict: a higher-priority UAS is moved only when that buys more than this",
        min=0.0,
    )
    risk_length_scale_m: float = setting(
        200.0,
        "length inside geofences counted as one unit of risk",
        min=1.0,
        unit="m",
    )
    risk_outside_ov_scale_m: float = setting(
        1000.0,
        "length outside the plan's operational volume counted as one unit of risk (a detour is "
        "outside by design: weighed lighter than flying inside a geofence)",
        min=1.0,
        unit="m",
    )
    risk_proximity_factor: float = setting(
        3.0,
        "proximity risk falls linearly from 1 at the minimum distance to 0 at this many times it",
        min=1.01,
    )
    landing_reserve_fraction: float = setting(
        0.2,
        "share of the remaining endurance kept in reserve when checking reachability",
        min=0.0,
        max=0.9,
    )
    max_neighbours: int = setting(
        12, "at most this many other operations enter one charged-cord problem", min=1
    )
