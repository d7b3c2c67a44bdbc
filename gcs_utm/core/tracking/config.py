"""Settings of the Tracking module (``[tracking]`` in the configuration).

Every field is declared with :func:`gcs_utm.config.setting` so ``config/default.toml`` is
generated from this class. Units are in the names: metres, seconds, metres per second.
Constructing the class checks every range, so a hand-built config is as safe as a loaded one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from gcs_utm.config import check_range, setting


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackingConfig:
    # ---- process noise: white acceleration of the constant-velocity model ------------------
    accel_sigma_h_mps2: float = setting(
        2.0, "1-sigma white acceleration, horizontal axes", min=0.001, max=100.0, unit="m/s^2"
    )
    accel_sigma_v_mps2: float = setting(
        1.0, "1-sigma white acceleration, vertical axis", min=0.001, max=100.0, unit="m/s^2"
    )
    # ---- measurement noise when the measurement does not carry its own accuracy ------------
    telemetry_eph_m: float = setting(
        3.0,
        "default horizontal 1-sigma of MAVLink telemetry (GNSS eph unknown)",
        min=0.01,
        unit="m",
    )
    telemetry_epv_m: float = setting(
        5.0,
        "default vertical 1-sigma of MAVLink telemetry (GNSS epv unknown)",
        min=0.01,
        unit="m",
    )
    adsb_eph_m: float = setting(
        15.0, "default horizontal 1-sigma of ADS-B (NACp unknown)", min=0.01, unit="m"
    )
    adsb_epv_m: float = setting(
        10.0, "default vertical 1-sigma of ADS-B (25 ft barometric steps)", min=0.01, unit="m"
    )
    mqtt_eph_m: float = setting(
        10.0, "default horizontal 1-sigma of positions relayed over MQTT", min=0.01, unit="m"
    )
    mqtt_epv_m: float = setting(
        10.0, "default vertical 1-sigma of positions relayed over MQTT", min=0.01, unit="m"
    )
    telemetry_vel_sigma_mps: float = setting(
        0.5, "1-sigma of a measured velocity from telemetry/MQTT", min=0.01, unit="m/s"
    )
    adsb_vel_sigma_mps: float = setting(
        2.0, "1-sigma of an ADS-B velocity (NACv unknown)", min=0.01, unit="m/s"
    )
    min_sigma_m: float = setting(
        0.3,
        "floor on any position 1-sigma (a reported 0 would make the filter overconfident)",
        min=0.001,
        unit="m",
    )
    initial_vel_sigma_mps: float = setting(
        10.0,
        "1-sigma of the velocity of a new track without a measured velocity",
        min=0.01,
        unit="m/s",
    )
    # ---- validation gates --------------------------------------------------------------------
    max_speed_mps: float = setting(
        350.0,
        "fastest plausible target (covers airliners on ADS-B); faster implied motion is rejected",
        min=1.0,
        unit="m/s",
    )
    max_jump_m: float = setting(
        10_000.0,
        "largest plausible distance between a measurement and the predicted track",
        min=1.0,
        unit="m",
    )
    gate_margin_m: float = setting(
        50.0,
        "distance always allowed on top of max_speed_mps * dt (noise, short dt)",
        min=0.0,
        unit="m",
    )
    gate_reset_count: int = setting(
        5,
        "after this many consecutive gate rejections of a stale track, restart it from the "
        "next valid measurement (a wrong first fix must not lock a track out)",
        min=1,
    )
    max_future_s: float = setting(
        5.0,
        "reject a measurement whose capture time is this far after its receipt time",
        min=0.0,
        unit="s",
    )
    # ---- batching (the tracking service) -----------------------------------------------------
    ingest_delay_s: float = setting(
        0.001,
        "a received measurement updates its track at most this long after it arrived; "
        "measurements arriving within it are fused as one batch in capture-time order "
        "(the reorder window)",
        min=0.0,
        max=0.1,
        unit="s",
    )
    # ---- staleness ---------------------------------------------------------------------------
    stale_after_s: float = setting(
        5.0, "a track without an accepted measurement for this long is stale", min=0.1, unit="s"
    )
    intruder_drop_after_s: float = setting(
        60.0, "an intruder track silent for this long is removed", min=1.0, unit="s"
    )
    # ---- prediction --------------------------------------------------------------------------
    horizon_s: float = setting(60.0, "prediction horizon", min=0.0, max=3600.0, unit="s")
    step_s: float = setting(1.0, "prediction step", min=0.01, max=600.0, unit="s")
    plan_follow_factor: float = setting(
        1.0,
        "follow the plan while within this many flight geometries (flight_geometry_m) of it",
        min=0.0,
        max=100.0,
    )
    plan_ambiguity_factor: float = setting(
        1.0,
        "segments within min distance + this many flight geometries compete for the "
        "current waypoint; the plan time decides among them",
        min=0.0,
        max=100.0,
    )
    plan_sigma_growth_mps: float = setting(
        1.0,
        "growth rate of the uncertainty radius while following the plan",
        min=0.0,
        unit="m/s",
    )
    plan_offset_decay_s: float = setting(
        10.0,
        "time constant with which a cross-track offset shrinks when following the plan",
        min=0.01,
        unit="s",
    )
    plan_offset_persist_s: float = setting(
        10.0,
        "an altitude offset from the plan seen on one side of it for this long persists: "
        "the prediction keeps it (its smallest size over the last one to two such spans) "
        "instead of decaying it",
        min=0.5,
        max=3600.0,
        unit="s",
    )

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check_range(
                "TrackingConfig", f"tracking.{f.name}", getattr(self, f.name), dict(f.metadata)
            )

    @property
    def n_points(self) -> int:
        """Points per predicted trajectory: now, then every ``step_s`` up to ``horizon_s``."""
        return round(self.horizon_s / self.step_s) + 1
