"""``gcs-utm replay INPUT... [--speed N|max] [--report OUT.json]``: recorded ``.tlog`` files,
ADS-B receiver captures (``.sbs``, ``.bin``, ``.avr``) and folders written by ``--record``
run through the service's own parts, as live links and feeds do (MAVLink hub / ADS-B
decoders -> Tracking -> Monitoring), on record time, with a progress bar on stderr and a JSON
report.

The replay configuration of the service: :mod:`gcs_utm.app.replay`; reading and merging the
inputs: :mod:`gcs_utm.cli.replay_inputs`. Bad input, one line on stderr: a missing path, a file of
unknown kind or a folder without recordings is exit 2; inputs without a single valid record
(or a capture that cannot be timed) exit 1.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from adapters.adsb.config import AdsbConfig
from gcs_utm.app.replay import ReplayConfig
from gcs_utm.cli.replay_inputs import Inputs, ReplayError, discover, first_t_s, replay_inputs
from gcs_utm.scenario import ScenarioError

__all__ = [
    "ReplayConfig",
    "ReplayError",
    "parse_speed",
    "register",
    "replay_file",
    "replay_paths",
    "scenario_config",
]


async def replay_paths(
    paths: Sequence[Path],
    *,
    speed: float | None = None,
    config: ReplayConfig | None = None,
    on_progress: Callable[[int], None] | None = None,
    adsb: AdsbConfig | None = None,
    adsb_start_t_s: float | None = None,
) -> dict[str, Any]:
    """Replay ``paths`` (tlogs, captures, recorded folders) merged by time and return the
    report; ``adsb`` configures the capture decoders (receiver position). The replay runs on
    an event loop of its own, in a worker thread. Raises :class:`ReplayError`."""
    return await asyncio.to_thread(
        replay_inputs,
        discover(paths),
        speed=speed,
        config=config,
        on_progress=on_progress,
        adsb=adsb,
        adsb_start_t_s=adsb_start_t_s,
    )


async def replay_file(
    path: Path,
    *,
    speed: float | None = None,
    config: ReplayConfig | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Replay the one file ``path`` (a tlog or an ADS-B capture); see :func:`replay_paths`.
    ``on_progress(bytes_done)`` is called every few hundred records."""
    if not path.is_file():
        raise ReplayError(path, _not_a_file(path))
    return await replay_paths([path], speed=speed, config=config, on_progress=on_progress)


def scenario_config(
    inputs: Inputs,
    scenario_path: Path,
    base: ReplayConfig | None = None,
    *,
    t0_s: float | None = None,
) -> ReplayConfig:
    """The replay configuration with the operations, geofences and frame of
    ``scenario_path``, its t0 at ``t0_s`` (default: the first record time of ``inputs``);
    ``base`` gives the settings."""
    from gcs_utm.scenario import load_any

    t0 = first_t_s(inputs) if t0_s is None else t0_s
    if t0 is None:
        raise ReplayError(inputs.files[0], "no valid tlog record: not a .tlog file?")
    scenario = load_any(scenario_path, t0_s=t0)
    b = base or ReplayConfig()
    settings = b.settings
    if scenario.safety_distance_m is not None:  # as `run` does with such a scenario
        settings = replace(settings, monitoring=scenario.monitoring_for(settings.monitoring))
    return ReplayConfig(
        settings=settings,
        link=f"tlog:{inputs.files[0].name}",
        frame=scenario.frame,
        operations=tuple(scenario.operations),
        geofences=tuple(scenario.geofences),
    )


def _not_a_file(path: Path) -> str:
    return "is a directory, not a .tlog file" if path.is_dir() else "no such file"


def parse_speed(text: str) -> float | None:
    """``max`` (as fast as possible) or a positive factor (1 = real time). ``0`` is refused,
    not read as ``max``: a factor of 0 would mean a stopped clock."""
    if text.strip().lower() in ("max", "inf"):
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a positive number or 'max', got {text!r}"
        ) from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a positive number or 'max', got {text!r}")
    return value


def parse_utc(text: str) -> float:
    """``--adsb-start``: POSIX seconds or an ISO 8601 time (UTC unless it names its zone)."""
    try:
        return float(text)
    except ValueError:
        pass
    try:
        stamp = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected POSIX seconds or an ISO 8601 time such as 2026-01-23T10:57:03Z, got {text!r}"
        ) from None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    return stamp.timestamp()


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "replay",
        help="replay tlogs, ADS-B captures or a --record folder through tracking and "
        "monitoring and write a JSON report",
        description="Replay .tlog files, ADS-B receiver captures (.sbs SBS-1, .bin Beast, "
        ".avr AVR) and folders recorded with --record into the telemetry -> tracking -> "
        "monitoring parts of the service, merged by time, each at its record time. "
        "Corrupt records are skipped and counted.",
    )
    p.add_argument(
        "inputs",
        type=Path,
        nargs="+",
        metavar="FILE|DIR",
        help="a .tlog, an ADS-B capture (.sbs, .bin, .avr) or a folder written by --record",
    )
    p.add_argument(
        "--speed",
        type=parse_speed,
        default=None,
        metavar="N|max",
        help="1 = real time, N = N times faster, max = as fast as possible (default)",
    )
    p.add_argument(
        "--report",
        type=Path,
        default=None,
        help="JSON report path (default: ./<name of the first input>.replay.json)",
    )
    p.add_argument(
        "--scenario",
        type=Path,
        default=None,
        help="scenario file whose operations/geofences apply (its t0 = the first record time)",
    )
    p.add_argument(
        "--scenario-t0",
        type=parse_utc,
        default=None,
        metavar="UTC",
        help="the scenario's t0 (POSIX seconds or ISO 8601; default: the first record time): "
        "the t0 of the run that recorded the inputs",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="settings TOML: its [tracking], [monitoring], [mavlink] and [adsb] (receiver "
        "position for Beast/AVR) apply",
    )
    p.add_argument(
        "--adsb-start",
        type=parse_utc,
        default=None,
        metavar="UTC",
        help="time of the first frame of a Beast/AVR capture without a .times sidecar "
        "(default: the first tlog record, else the capture file's modification time)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=_run)


def _prepare(args: argparse.Namespace) -> tuple[Inputs, ReplayConfig, Any] | int:
    """Inputs, replay configuration and ADS-B settings of the command line, or an exit
    code."""
    from gcs_utm.config import ConfigError
    from gcs_utm.settings import load_settings

    paths: list[Path] = args.inputs
    for path in paths:
        if not path.exists():
            print(f"gcs-utm replay: {path}: no such file", file=sys.stderr)
            return 2
    try:
        inputs = discover(paths)
    except ReplayError as exc:  # an input that is no recording at all: a usage error
        print(f"gcs-utm replay: {exc}", file=sys.stderr)
        return 2
    try:
        settings = load_settings(args.config)
        config = ReplayConfig(settings=settings, link=f"tlog:{inputs.files[0].name}")
        if args.scenario is not None:
            config = scenario_config(inputs, args.scenario, config, t0_s=args.scenario_t0)
    except ConfigError as exc:
        print(f"gcs-utm replay: {exc}", file=sys.stderr)
        return 2
    except (ReplayError, ScenarioError, OSError) as exc:
        print(f"gcs-utm replay: {exc}", file=sys.stderr)
        return 1
    return inputs, config, settings.adsb


def _run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        DownloadColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    prepared = _prepare(args)
    if isinstance(prepared, int):
        return prepared
    inputs, config, adsb = prepared
    first: Path = args.inputs[0]
    out: Path = args.report or Path(f"{first.stem or first.resolve().name}.replay.json")
    total = inputs.total_bytes()
    progress = Progress(
        TextColumn("replay {task.description}"),
        BarColumn(),
        DownloadColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        disable=bool(args.no_progress),
    )
    with progress:
        task = progress.add_task(first.name, total=total)
        try:
            report = replay_inputs(
                inputs,
                speed=args.speed,
                config=config,
                on_progress=lambda done: progress.update(task, completed=done),
                adsb=adsb,
                adsb_start_t_s=args.adsb_start,
            )
        except ReplayError as exc:
            progress.stop()
            print(f"gcs-utm replay: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            progress.stop()
            print("gcs-utm replay: interrupted", file=sys.stderr)
            return 130
        progress.update(task, completed=total)
    try:
        out.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    except OSError as exc:
        print(f"gcs-utm replay: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    c = report["counters"]
    print(
        f"{report['records']} records, {c['adsb_capture_measurements']} ADS-B positions, "
        f"{report['duration']['duration_s']:.1f} s, "
        f"{len(report['vehicles'])} vehicles, {len(report['tracks'])} tracks, "
        f"{len(report['threats'])} threats, {c['corrupt_records']} corrupt records, "
        f"{sum(c['rejected_measurements'].values())} rejected measurements -> {out}"
    )
    return 0
