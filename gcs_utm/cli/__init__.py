"""Command line: ``gcs-utm``. Subcommands are modules of this package that define
``register(sub)``; they are discovered here so each lives next to the code it drives, and
listed in :data:`COMMANDS` so that only the module of the command run is imported.

This is the top layer: the one place (with :mod:`gcs_utm.app`) that sets up logging.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Sequence
from typing import Any

from gcs_utm import __version__

COMMANDS: dict[str, tuple[str, str]] = {
    "bench": ("bench", "run performance benchmarks (JSON output)"),
    "config": ("config", "print the default configuration or check a file"),
    "eval": (
        "eval",
        "run scenarios end to end in fast time with an automatic operator and summarise the "
        "resolutions (JSON and markdown)",
    ),
    "pilot": ("pilot", "remote pilot station: show recommendations over MQTT and answer them"),
    "plot": ("plot", "draw figures and GeoJSON/KML from a run report"),
    "replay": (
        "replay",
        "replay tlogs, ADS-B captures or a --record folder through tracking and monitoring "
        "and write a JSON report",
    ),
    "run": (
        "run",
        "run a scenario end to end (vehicles, UTM services, dashboard) and write a report",
    ),
    "demo": ("run", "the paper's use cases 1 and 2 with built-in vehicles"),
    "serve": ("run", "the long-running UTM service (links from config)"),
    "scenario": ("scenario", "scenario tools"),
    "sitl": ("sitl", "run the simulated vehicles of a scenario file (PX4-like, MAVLink over UDP)"),
}
"""Command -> (module of this package that registers it, its one-line help). ``main`` imports
only the module of the command given (NumPy, pymavlink, the app, ... are imported by the
commands that use them), so ``gcs-utm --help`` and quick commands start fast; the other
commands are listed with this help. A test checks it against what the modules register."""


def _top_parser() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction[Any]]:
    parser = argparse.ArgumentParser(
        prog="gcs-utm",
        description="UAS Traffic Management ground service (U-space in-flight services) over "
        "MAVLink for PX4 / ArduPilot.",
    )
    parser.add_argument("--version", action="version", version=f"gcs-utm {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    return parser, sub


def _register(module_name: str, sub: argparse._SubParsersAction[Any]) -> None:
    module = importlib.import_module(f"{__name__}.{module_name}")
    register = getattr(module, "register", None)
    if callable(register):
        register(sub)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The full parser (every command's module imported), or with ``command`` only that
    command's module imported and the others listed by name and help."""
    parser, sub = _top_parser()
    if command is None:
        modules = sorted(
            info.name for info in pkgutil.iter_modules(__path__) if not info.name.startswith("_")
        )
        for name in modules:
            _register(name, sub)
        return parser
    wanted = COMMANDS[command][0]
    _register(wanted, sub)
    for name, (module_name, help_text) in COMMANDS.items():
        if module_name != wanted:
            sub.add_parser(name, help=help_text)
    return parser


def _command_of(argv: Sequence[str]) -> str | None:
    """The command word of ``argv`` (the first argument that is not an option: the top
    level's options take no value), if it is a known command."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else None
    return None


def _listing() -> argparse.ArgumentParser:
    """Every command by name and help, none imported (``--help``, no or unknown command)."""
    parser, sub = _top_parser()
    for name, (_, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args_in = sys.argv[1:] if argv is None else list(argv)
    command = _command_of(args_in)
    parser = build_parser(command) if command is not None else _listing()
    args = parser.parse_args(args_in)
    level = logging.WARNING - 10 * min(int(args.verbose), 2)
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    code = func(args)
    return int(code)


if __name__ == "__main__":
    sys.exit(main())
