"""``gcs-utm replay INPUT... [--speed N|max] [--report OUT.json]``: recorded ``.tlog`` files,
ADS-B receiver captures (``.sbs``, ``.bin``, ``.avr``) and folders written by ``--record``
run through the same pipeline as live links and feeds (MAVLink telemetry decoder / ADS-B
decoders -> Tracking -> Monitoring), with a progress bar on stderr and a JSON report.

The pipeline: :mod:`gcs_utm.cli.replay_pipeline`; reading and merging the inputs:
:mod:`gcs_utm.cli.replay_inputs`. Bad input, one line on stderr: a missing path, a file of
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
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from adapters.adsb.config import AdsbConfig
from gcs_utm.cli.replay_inputs import Inputs, discover, first_t_s, replay_inputs
from gcs_utm.cli.replay_pipeline import ReplayError, ReplayPipeline
from gcs_utm.scenario import ScenarioError

__all__ = [
    "ReplayError",
    "ReplayPipeline",
    "parse_speed",
    "register",
    "replay_file",
    "replay_paths",
    "scenario_pipeline",
]


async def replay_paths(
    paths: Sequence[Path],
    *,
    speed: float | None = None,
    pipeline: ReplayPipeline | None = None,
    on_progress: Callable[[int], None] | None = None,
    adsb: AdsbConfig | None = None,
    adsb_start_t_s: float | None = None,
) -> dict[str, Any]:
    """Replay ``paths`` (tlogs, captures, recorded folders) merged by time and return the
    report; ``adsb`` configures the capture decoders (receiver position). Raises
    :class:`ReplayError`."""
    return await replay_inputs(
        discover(paths),
        speed=speed,
        pipeline=pipeline,
        on_progress=on_progress,
        adsb=adsb,
        adsb_start_t_s=adsb_start_t_s,
    )


async def replay_file(
    path: Path,
    *,
    speed: float | None = None,
    pipeline: ReplayPipeline | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Replay the one file ``path`` (a tlog or an ADS-B capture); see :func:`replay_paths`.
    ``on_progress(bytes_done)`` is called every few hundred records."""
    if not path.is_file():
        raise ReplayError(path, _not_a_file(path))
    return await replay_paths([path], speed=speed, pipeline=pipeline, on_progress=on_progress)


def scenario_pipeline(
    inputs: Inputs, scenario_path: Path, base: ReplayPipeline | None = None
) -> ReplayPipeline:
    """A pipeline with the operations and geofences of ``scenario_path``, its t0 set to the
    first record time of ``inputs``; ``base`` gives the settings (mavlink, tracking,
    monitoring)."""
    from gcs_utm.scenario import load_any

    t0 = first_t_s(inputs)
    if t0 is None:
        raise ReplayError(inputs.files[0], "no valid tlog record: not a .tlog file?")
    scenario = load_any(scenario_path, t0_s=t0)
    b = base or ReplayPipeline()
    return ReplayPipeline(
        link=f"tlog:{inputs.files[0].name}",
        mavlink=b.mavlink,
        tracking=b.tracking,
        monitoring=b.monitoring,
        remote_id=b.remote_id_config,
        frame=scenario.frame,
        operations=scenario.operations,
        geofences=scenario.geofences,
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
        "monitoring pipeline, merged by time, using record times as capture times. "
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


def _prepare(args: argparse.Namespace) -> tuple[Inputs, ReplayPipeline | None, Any] | int:
    """Inputs, pipeline and ADS-B settings of the command line, or an exit code."""
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
        pipeline = ReplayPipeline(
            link=f"tlog:{inputs.files[0].name}",
            mavlink=settings.mavlink,
            tracking=settings.tracking,
            monitoring=settings.monitoring,
            remote_id=settings.remote_id,
        )
        if args.scenario is not None:
            pipeline = scenario_pipeline(inputs, args.scenario, pipeline)
    except ConfigError as exc:
        print(f"gcs-utm replay: {exc}", file=sys.stderr)
        return 2
    except (ReplayError, ScenarioError, OSError) as exc:
        print(f"gcs-utm replay: {exc}", file=sys.stderr)
        return 1
    return inputs, pipeline, settings.adsb


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
    inputs, pipeline, adsb = prepared
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
            report = asyncio.run(
                replay_inputs(
                    inputs,
                    speed=args.speed,
                    pipeline=pipeline,
                    on_progress=lambda done: progress.update(task, completed=done),
                    adsb=adsb,
                    adsb_start_t_s=args.adsb_start,
                )
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
