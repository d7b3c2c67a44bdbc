"""All configuration sections composed into one :class:`Settings` (the ``config/default.toml``
file is rendered from :data:`SECTIONS`; ``gcs-utm config default`` prints it).

This module sits just below the composition root: it may import every area's settings class.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adapters.adsb.config import AdsbConfig
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.traffic_out import TrafficOutConfig
from adapters.mqtt.config import MqttConfig
from adapters.remoteid.config import RemoteIdConfig
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.config import ConfigError, build, load_toml, setting
from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.emergency.config import EmergencyConfig
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.tracking.config import TrackingConfig
from gcs_utm.dashboard.config import DashboardConfig
from gcs_utm.preflight import check_settings
from gcs_utm.services.record_config import RecordConfig
from gcs_utm.services.usm import UsmConfig
from gcs_utm.store.config import StoreConfig


@dataclass(frozen=True, slots=True, kw_only=True)
class AirspaceConfig:
    """The airspace ``gcs-utm serve`` manages (scenario runs take it from the scenario)."""

    origin_lat_deg: float = setting(
        45.467116, "origin latitude (default: PX4 v1.15 SIH's default home)", min=-80.0, max=84.0
    )
    origin_lon_deg: float = setting(-73.757837, "origin longitude", min=-180.0, max=180.0)
    ground_elevation_amsl_m: float = setting(
        32.34, "ground elevation used to convert AGL to AMSL", min=-500.0, max=9000.0, unit="m"
    )


def _section(cls: type[Any], doc: str) -> Any:
    return field(default_factory=cls, metadata={"doc": doc, "min": None, "max": None, "unit": ""})


@dataclass(frozen=True, slots=True, kw_only=True)
class Settings:
    airspace: AirspaceConfig = _section(AirspaceConfig, "airspace")
    tracking: TrackingConfig = _section(TrackingConfig, "tracking")
    monitoring: MonitoringConfig = _section(MonitoringConfig, "monitoring")
    deconfliction: DeconflictionConfig = _section(DeconflictionConfig, "deconfliction")
    emergency: EmergencyConfig = _section(EmergencyConfig, "emergency")
    usm: UsmConfig = _section(UsmConfig, "usm")
    mavlink: MavlinkConfig = _section(MavlinkConfig, "mavlink")
    adsb: AdsbConfig = _section(AdsbConfig, "adsb")
    mqtt: MqttConfig = _section(MqttConfig, "mqtt")
    store: StoreConfig = _section(StoreConfig, "store")
    dashboard: DashboardConfig = _section(DashboardConfig, "dashboard")
    record: RecordConfig = _section(RecordConfig, "record")
    cluster: ClusterConfig = _section(ClusterConfig, "cluster")
    remote_id: RemoteIdConfig = _section(RemoteIdConfig, "remote_id")
    traffic_out: TrafficOutConfig = _section(TrafficOutConfig, "traffic_out")


SECTIONS: dict[str, type[Any]] = {
    "airspace": AirspaceConfig,
    "tracking": TrackingConfig,
    "monitoring": MonitoringConfig,
    "deconfliction": DeconflictionConfig,
    "emergency": EmergencyConfig,
    "usm": UsmConfig,
    "mavlink": MavlinkConfig,
    "adsb": AdsbConfig,
    "mqtt": MqttConfig,
    "store": StoreConfig,
    "dashboard": DashboardConfig,
    "record": RecordConfig,
    "cluster": ClusterConfig,
    "remote_id": RemoteIdConfig,
    "traffic_out": TrafficOutConfig,
}


def settings_from_mapping(doc: Mapping[str, Any], *, source: str) -> Settings:
    """Validate a whole configuration document; unknown sections are errors too."""
    unknown = sorted(set(doc) - set(SECTIONS))
    if unknown:
        raise ConfigError(
            source, unknown[0], "unknown section; valid sections are: " + ", ".join(SECTIONS)
        )
    parts = {
        name: build(cls, doc.get(name, {}), source=source, section=name)
        for name, cls in SECTIONS.items()
    }
    return Settings(**parts)


def load_settings(path: str | Path | None = None) -> Settings:
    """The embedded defaults, overlaid with ``path`` when given, and checked as ``serve``
    will use them (:func:`gcs_utm.preflight.check_settings`): a file that loads here does
    not fail later on a link string, a key, a certificate file or an inverted range."""
    if path is None:
        return Settings()
    settings = settings_from_mapping(load_toml(path), source=str(path))
    check_settings(settings, source=str(path))
    return settings
