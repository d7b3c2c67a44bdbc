"""``gcs-utm config default`` prints every setting with its default and doc;
``gcs-utm config check FILE`` validates a configuration file against the settings classes.
``gcs-utm config mqtt-acl`` prints the broker's ACL (:mod:`adapters.mqtt.acl`).

Sections come from ``gcs_utm.settings.SECTIONS``.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from gcs_utm.config import ConfigError, build, load_toml, render_toml
from gcs_utm.preflight import check_resources, check_settings
from gcs_utm.settings import SECTIONS, Settings


def sections() -> dict[str, type[Any]]:
    """The configuration sections: name -> settings dataclass."""
    return dict(SECTIONS)


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("config", help="print the default configuration or check a file")
    cmds = p.add_subparsers(dest="config_command", metavar="ACTION", required=True)
    d = cmds.add_parser("default", help="print every setting with its default, as TOML")
    d.set_defaults(func=_default)
    c = cmds.add_parser("check", help="validate a configuration TOML file")
    c.add_argument("file", help="configuration file (TOML)")
    c.set_defaults(func=_check)
    a = cmds.add_parser(
        "mqtt-acl", help="print the mosquitto ACL that confines each operator to its topics"
    )
    a.add_argument("--prefix", default="gcs_utm", help="[mqtt] topic_prefix (default gcs_utm)")
    a.add_argument(
        "--utm-user", default="gcs_utm", help="broker user name of gcs-utm (default gcs_utm)"
    )
    a.set_defaults(func=_mqtt_acl)


def _default(args: argparse.Namespace) -> int:
    sys.stdout.write(render_toml(sections()))
    return 0


def _mqtt_acl(args: argparse.Namespace) -> int:
    from adapters.mqtt.acl import mosquitto_acl

    try:
        text = mosquitto_acl(args.prefix, utm_user=args.utm_user)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    sys.stdout.write(text)
    return 0


def check_file(path: str) -> dict[str, Any]:
    """Load and validate every section of ``path``, then check the whole as ``serve``'s start
    will (:mod:`gcs_utm.preflight`: link strings, signing keys, TLS files, ranges across
    keys, duplicate links; links bindable); returns section -> settings object for the
    sections the file sets."""
    known = sections()
    doc = load_toml(path)
    out: dict[str, Any] = {}
    for name, table in doc.items():
        if name not in known:
            raise ConfigError(
                path, name, "unknown section; valid sections are: " + ", ".join(sorted(known))
            )
        out[name] = build(known[name], table, source=path, section=name)
    settings = Settings(**{n: v for n, v in out.items() if n in Settings.__dataclass_fields__})
    check_settings(settings, source=path)
    check_resources(settings, source=path)  # what serve's start opens: links bind
    return out


def _check(args: argparse.Namespace) -> int:
    try:
        loaded = check_file(args.file)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = ", ".join(loaded) or "none (all defaults)"
    print(f"{args.file}: ok; sections set: {names}")
    return 0
