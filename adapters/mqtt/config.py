"""Settings of the MQTT door of the U-space Service Manager (section ``[mqtt]``).

Every field is declared with :func:`gcs_utm.config.setting` so ``config/default.toml`` is
generated from this class. Secrets (password, key file) are plain settings here; deployments
should point them at files readable only by the service user.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class MqttTlsConfig:
    """TLS towards the broker. TLS is on when ``enabled`` is true."""

    enabled: bool = setting(False, "connect with TLS")
    ca_path: str = setting("", "CA certificate file (PEM); empty: the system trust store")
    cert_path: str = setting("", "client certificate file (PEM) for mutual TLS; empty: none")
    key_path: str = setting("", "client private key file (PEM) for mutual TLS; empty: none")
    insecure: bool = setting(
        False, "skip the broker host-name check (test benches only; never in operation)"
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class MqttConfig:
    """How the USM talks JSON over MQTT to remote pilot stations and stakeholders."""

    enabled: bool = setting(False, "start the MQTT bridge")
    host: str = setting("127.0.0.1", "broker host name or address")
    port: int = setting(1883, "broker TCP port", min=1, max=65535)
    username: str = setting("", "broker user name of the UTM; empty: anonymous")
    password: str = setting("", "broker password of the UTM")
    tls: MqttTlsConfig = field(
        default_factory=MqttTlsConfig,
        metadata={"doc": "TLS settings", "min": None, "max": None, "unit": ""},
    )
    topic_prefix: str = setting("gcs_utm", "first topic level of every gcs-utm topic")
    client_id: str = setting(
        "gcs-utm",
        "MQTT client id; fixed so the broker keeps the session (queued QoS 1 answers) "
        "across reconnects",
    )
    session_expiry_s: int = setting(
        3600,
        "MQTT 5 session expiry interval: how long the broker keeps the UTM's session "
        "(subscriptions, queued QoS 1 answers) while the UTM is away",
        min=0,
        max=4_294_967_295,
        unit="s",
    )
    keepalive_s: int = setting(30, "MQTT keepalive interval", min=5, max=3600, unit="s")
    queue_max: int = setting(
        1000,
        "outgoing messages kept while the broker is unreachable; the oldest is dropped "
        "(and logged) beyond this",
        min=1,
        max=1_000_000,
    )
    backoff_initial_s: float = setting(
        0.5, "first reconnect delay (doubles each failure, full jitter)", min=0.01, unit="s"
    )
    backoff_max_s: float = setting(30.0, "reconnect delay cap", min=0.01, unit="s")
    traffic_rate_hz: float = setting(
        1.0, "maximum rate of traffic-information messages", min=0.01, max=50.0, unit="Hz"
    )
    connect_timeout_s: float = setting(
        10.0, "time allowed for connect + subscribe before retrying", min=0.1, unit="s"
    )
    publish_timeout_s: float = setting(
        10.0, "time to wait for the broker's acknowledgement of one publish", min=0.1, unit="s"
    )
