"""One way to open an MQTT 5 session from ``[mqtt]`` settings, for the bridge and the pilot
station alike: a persistent session (clean start off, ``session_expiry_s``), the configured
credentials, keepalive, publish timeout and TLS. Each caller names its own session
(``identifier``) and adds what only it needs (the bridge's will and inbox queue)."""

from __future__ import annotations

import ssl
from typing import Any

import aiomqtt
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from adapters.mqtt.config import MqttConfig


def session_client(cfg: MqttConfig, identifier: str, **extra: Any) -> aiomqtt.Client:
    """An ``aiomqtt.Client`` for ``cfg`` under client id ``identifier``; ``extra`` goes to
    ``aiomqtt.Client`` as it is."""
    tls_params = None
    if cfg.tls.enabled:
        tls_params = aiomqtt.TLSParameters(
            ca_certs=cfg.tls.ca_path or None,
            certfile=cfg.tls.cert_path or None,
            keyfile=cfg.tls.key_path or None,
            cert_reqs=ssl.CERT_REQUIRED,
        )
    connect = Properties(PacketTypes.CONNECT)  # type: ignore[no-untyped-call]
    connect.SessionExpiryInterval = cfg.session_expiry_s
    return aiomqtt.Client(
        cfg.host,
        cfg.port,
        username=cfg.username or None,
        password=cfg.password or None,
        identifier=identifier,
        protocol=aiomqtt.ProtocolVersion.V5,
        clean_start=False,
        properties=connect,
        keepalive=cfg.keepalive_s,
        timeout=cfg.publish_timeout_s,
        tls_params=tls_params,
        tls_insecure=cfg.tls.insecure if cfg.tls.enabled else None,
        **extra,
    )


__all__ = ["session_client"]
