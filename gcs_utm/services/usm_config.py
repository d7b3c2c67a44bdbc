"""The USM's settings (section ``[usm]``), a module of their own so that the USM's parts
can be configured without importing the USM."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class UsmConfig:
    """USM behaviour (section ``[usm]``)."""

    hazard_cooldown_s: float = setting(
        30.0,
        "a hazard of the same kind for the same UAS within this time is coalesced, not re-raised",
        min=0.0,
        unit="s",
    )
    event_log_size: int = setting(500, "events kept for the dashboard", min=10)
    threat_log_size: int = setting(
        10_000,
        "threat openings and closings kept in memory for the run report, without the "
        "prediction each was computed on (the store keeps every one); the oldest are dropped "
        "and counted beyond it",
        min=10,
    )
    upload_attempts: int = setting(
        2,
        "whole-mission upload attempts (each with the link's own per-item retries) before a "
        "recommendation is marked failed",
        min=1,
        max=10,
    )
    default_priority: int = setting(1, "priority of an operation created from a vehicle")
    default_flight_geometry_m: float = setting(
        10.0, "flight-geometry radius of an operation created from a vehicle", min=0.1, unit="m"
    )
    default_operational_volume_m: float = setting(
        30.0,
        "operational-volume radius of an operation created from a vehicle",
        min=0.1,
        unit="m",
    )
    default_cruise_speed_mps: float = setting(
        5.0,
        "cruise speed assumed for a vehicle's downloaded mission without speed items",
        min=0.1,
        unit="m/s",
    )
    default_fixed_wing_cruise_speed_mps: float = setting(
        22.0,
        "a fixed wing's cruise airspeed, for its downloaded mission without speed items "
        "(ArduPlane AIRSPEED_CRUISE in its SITL defaults; PX4 FW_AIRSPD_TRIM is 15)",
        min=0.1,
        unit="m/s",
    )
    home_tolerance_m: float = setting(
        1.0,
        "a vehicle's home (HOME_POSITION after its first 3D fix) moving more than this "
        "vertically (2 m horizontally) re-files its operation, and at arming whatever the move",
        min=0.01,
        unit="m",
    )
    ground_warning_m: float = setting(
        50.0,
        "warn (once per vehicle) when a vehicle's home altitude is further than this from "
        "[airspace] ground_elevation_amsl_m",
        min=0.0,
        unit="m",
    )
    # Bounds of state keyed by identities a sender chooses (ICAO addresses, alert ids).
    max_adsb_sources: int = setting(
        4096,
        "ADS-B sources (ICAO addresses) with statistics of their own; when full, the least "
        "recently heard eighth is folded into 'adsb:evicted' (counted in adsb_sources_evicted)",
        min=8,
        max=1_000_000,
    )
    threat_clear_s: float = setting(
        3.0,
        "a threat raised from a hazard closes when its cause (link loss, GNSS degradation, "
        "...) has been gone this long (docs/emergency.md, 'When a threat closes')",
        min=0.0,
        max=600.0,
        unit="s",
    )
    restart_review_s: float = setting(
        30.0,
        "after a restart, threats an earlier life left open that the new life does not detect "
        "again within this time are closed (docs/emergency.md, 'After a restart')",
        min=0.0,
        max=3600.0,
        unit="s",
    )
    max_hazard_keys: int = setting(
        4096,
        "hazard coalescing keys kept (one per kind and UAS or alert); a key older than "
        "hazard_cooldown_s is forgotten, and when full the oldest eighth (hazard_keys_evicted)",
        min=8,
        max=1_000_000,
    )
