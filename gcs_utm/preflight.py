"""Checks of a whole configuration that need more than one field's type and range: what
``serve`` would otherwise find only when it starts (or later, on the first reconnect).

- ``[mqtt] tls``: the CA, certificate and key files exist and load (the same ``ssl`` calls
  the MQTT client makes when it connects), a certificate comes with its key;
- ``[mqtt] topic_prefix``: a valid topic name without wildcards;
- reconnect backoffs: the first delay is not above the cap;
- ``[airspace]``: the origin makes a local frame;
- ``[mavlink] links``: no link listed twice.

:func:`check_resources` then opens what ``serve``'s start opens, and closes it again: every
``udpin`` link is bound (all of them at once, as ``serve`` holds them) and every ``udpout``
host resolves. ``config check`` and ``serve`` both run it.

``[mavlink]`` links and signing keys are checked by ``MavlinkConfig`` itself when the file is
loaded (the hub's own parser; 64 hex digits under a system id 1..255).

Every problem is a :class:`gcs_utm.config.ConfigError` naming the file, the dotted key and
what was expected. ``gcs-utm config check`` and every command that loads a configuration
file run these checks, so "ok" means ``serve`` will start with it.
"""

from __future__ import annotations

import contextlib
import socket
import ssl
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from adapters.mavlink.endpoint import EndpointError, EndpointKind, parse_endpoint
from gcs_utm.config import ConfigError
from gcs_utm.geo import FrameError, LocalFrame


def check_settings(settings: Any, *, source: str) -> None:
    """Raise :class:`ConfigError` for the first problem of ``settings`` (a
    :class:`gcs_utm.settings.Settings`), in section order."""
    for key, problem in _problems(settings):
        raise ConfigError(source, key, problem)


def problems(settings: Any) -> list[tuple[str, str]]:
    """Every (dotted key, what was expected) problem of ``settings``."""
    return list(_problems(settings))


def _problems(settings: Any) -> Iterator[tuple[str, str]]:
    yield from _airspace(settings.airspace)
    yield from _ordered(
        "adsb.reconnect_initial_s",
        settings.adsb.reconnect_initial_s,
        "adsb.reconnect_max_s",
        settings.adsb.reconnect_max_s,
    )
    yield from _mqtt(settings.mqtt)
    yield from _duplicate_links(settings.mavlink.links)


def _duplicate_links(links: tuple[str, ...]) -> Iterator[tuple[str, str]]:
    seen: dict[str, str] = {}
    for i, text in enumerate(links):
        try:
            ep = parse_endpoint(text)
        except EndpointError:
            continue  # MavlinkConfig refused it already
        name = str(ep)
        if ep.kind is EndpointKind.UDPIN and ep.port == 0:
            continue  # each binds a port of its own
        if name in seen:
            yield f"mavlink.links[{i}]", f"{text!r} is the same link as {seen[name]!r}"
        seen.setdefault(name, text)


def check_resources(settings: Any, *, source: str) -> None:
    """Raise :class:`ConfigError` for the first resource ``serve``'s start could not open
    (see the module docstring)."""
    for key, problem in resource_problems(settings):
        raise ConfigError(source, key, problem)


def resource_problems(settings: Any) -> list[tuple[str, str]]:
    """Every (dotted key, problem) of the sockets ``serve``'s start opens: each ``udpin`` link
    bound as the hub binds it (IPv4, all at once), each ``udpout`` host resolved."""
    out: list[tuple[str, str]] = []
    with contextlib.ExitStack() as held:
        for i, text in enumerate(settings.mavlink.links):
            try:
                ep = parse_endpoint(text)
            except EndpointError:
                continue
            try:
                if ep.kind is EndpointKind.UDPIN:
                    sock = held.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
                    sock.bind((ep.host, ep.port))
                elif ep.kind is EndpointKind.UDPOUT:
                    socket.gethostbyname(ep.host)
            except OSError as exc:
                what = "cannot be bound" if ep.kind is EndpointKind.UDPIN else "does not resolve"
                out.append((f"mavlink.links[{i}]", f"{text!r} {what}: {exc.strerror or exc}"))
    return out


def _airspace(air: Any) -> Iterator[tuple[str, str]]:
    try:
        LocalFrame(air.origin_lat_deg, air.origin_lon_deg, air.ground_elevation_amsl_m)
    except (FrameError, ValueError) as exc:
        yield "airspace.origin_lat_deg", f"the origin makes no local frame: {exc}"


def _ordered(lo_key: str, lo: float, hi_key: str, hi: float) -> Iterator[tuple[str, str]]:
    if lo > hi:
        yield lo_key, f"expected at most {hi_key} ({hi!r}), got {lo!r}"


def _mqtt(cfg: Any) -> Iterator[tuple[str, str]]:
    yield from _ordered(
        "mqtt.backoff_initial_s", cfg.backoff_initial_s, "mqtt.backoff_max_s", cfg.backoff_max_s
    )
    prefix = cfg.topic_prefix
    if (
        not prefix
        or any(c in prefix for c in "+#\0")
        or prefix.startswith("/")
        or prefix.endswith("/")
    ):
        yield (
            "mqtt.topic_prefix",
            (
                f"expected topic levels without wildcards (+, #) or a leading or trailing /, "
                f"got {prefix!r}"
            ),
        )
    if cfg.tls.enabled:
        yield from _tls(cfg.tls)


def _tls(tls: Any) -> Iterator[tuple[str, str]]:
    for name in ("ca_path", "cert_path", "key_path"):
        path = getattr(tls, name)
        if path and not Path(path).is_file():
            what = "is a directory" if Path(path).is_dir() else "does not exist"
            yield f"mqtt.tls.{name}", f"expected a readable PEM file; {path} {what}"
            return
    if bool(tls.cert_path) != bool(tls.key_path):
        missing = "key_path" if tls.cert_path else "cert_path"
        yield f"mqtt.tls.{missing}", "mutual TLS needs both cert_path and key_path"
        return
    ctx = ssl.create_default_context()
    if tls.ca_path:
        try:
            ctx.load_verify_locations(cafile=tls.ca_path)
        except (ssl.SSLError, OSError, ValueError) as exc:
            yield "mqtt.tls.ca_path", f"expected a PEM CA certificate file: {exc}"
            return
    if tls.cert_path:
        try:
            ctx.load_cert_chain(tls.cert_path, tls.key_path)
        except (ssl.SSLError, OSError, ValueError) as exc:
            yield "mqtt.tls.cert_path", f"the certificate and key do not load together: {exc}"


__all__ = ["check_resources", "check_settings", "problems", "resource_problems"]
