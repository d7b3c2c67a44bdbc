"""``gcs-utm run SCENARIO``, ``gcs-utm demo`` and ``gcs-utm serve``: the main jobs."""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gcs_utm.app import Report

DEMO_SCENARIOS = ("use_case_1.toml", "use_case_2.toml")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    run = sub.add_parser(
        "run",
        help="run a scenario end to end (vehicles, UTM services, dashboard) and write a report",
    )
    run.add_argument(
        "scenario", type=Path, help="scenario TOML, or a GAUSS JSON file or scenario YAML"
    )
    _common(run)
    run.add_argument(
        "--external",
        action="store_true",
        help="the vehicles are real PX4/ArduPilot SITL already running: start none "
        "and listen on --link (default: the first link of the config)",
    )
    run.add_argument(
        "--fly",
        action="store_true",
        help="with --external: upload each operation's plan to the vehicle with its sys_id, "
        "arm, take off and start the mission at the plan's first waypoint time",
    )
    run.add_argument(
        "--link",
        default=None,
        help="MAVLink connection string to listen on (default: an ephemeral "
        "loopback port the built-in vehicles are pointed at)",
    )
    run.add_argument(
        "--duration",
        type=float,
        default=None,
        help="simulated seconds to run (default: the scenario's duration_s)",
    )
    run.add_argument(
        "--reject-first",
        type=int,
        default=0,
        help="with --auto-accept: reject this many recommendations first",
    )
    run.set_defaults(func=_run)

    demo = sub.add_parser("demo", help="the paper's use cases 1 and 2 with built-in vehicles")
    _common(demo)
    demo.set_defaults(func=_demo, reject_first=0, external=False, link=None, duration=None)

    serve = sub.add_parser("serve", help="the long-running UTM service (links from config)")
    serve.add_argument("--config", type=Path, default=None, help="settings TOML")
    serve.add_argument(
        "--db",
        type=Path,
        default=Path("gcs_utm.sqlite"),
        help="SQLite store (kept across restarts; default ./gcs_utm.sqlite)",
    )
    serve.add_argument("--headless", action="store_true", help="no TUI; log lines")
    serve.add_argument(
        "--speed",
        type=positive_speed,
        default=1.0,
        help="the vehicles' simulation speed factor (PX4_SIM_SPEED_FACTOR, ArduPilot "
        "--speedup): the service's clock runs this many times faster than the wall clock "
        "(default 1: real vehicles)",
    )
    serve.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="DIR",
        help="record every MAVLink link (received and sent) as .tlog files and every ADS-B "
        "feed raw in DIR (rotation: [record]); gcs-utm replay DIR reads it back",
    )
    serve.add_argument(
        "--cluster",
        action="store_true",
        help="one of several instances sharing the [store] url PostgreSQL database and the "
        "[mqtt] broker: owns the [cluster] region, exchanges border traffic with its "
        "neighbours, takes over orphaned regions (docs/scale-out.md)",
    )
    group = serve.add_mutually_exclusive_group()
    group.add_argument("--auto-accept", action="store_true")
    group.add_argument("--auto-reject", action="store_true")
    serve.set_defaults(func=_serve)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=None, help="settings TOML")
    p.add_argument(
        "--speed",
        type=parse_speed,
        default=1.0,
        help="run N times faster than real time (vehicles and UTM share the factor), or "
        "'max': fast time, as fast as the computation allows, deterministic",
    )
    p.add_argument("--headless", action="store_true", help="no TUI; rich log lines on stderr")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--auto-accept", action="store_true", help="accept every recommendation")
    group.add_argument("--auto-reject", action="store_true", help="reject every recommendation")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("runs"),
        help="folder for the report, store and figures (default ./runs)",
    )
    p.add_argument("--no-figures", action="store_true", help="skip the PNG/GeoJSON/KML output")
    p.add_argument("--mqtt", action="store_true", help="start the MQTT bridge of the config")
    p.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="DIR",
        help="record every MAVLink link (received and sent) as .tlog files and every ADS-B "
        "feed raw in DIR (rotation: [record]); gcs-utm replay DIR reads it back",
    )


def positive_speed(text: str) -> float:
    """A speed factor: a finite number > 0 (0 would stop the clock, a negative one run it
    backwards); argparse turns the error into one usage line."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def parse_speed(text: str) -> float:
    """``run``/``demo --speed``: a speed factor (see :func:`positive_speed`), or ``max`` for
    fast time (``math.inf``: as fast as the computation allows)."""
    if text.strip().lower() == "max":
        return math.inf
    try:
        return positive_speed(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected a positive number or 'max', got {text!r}"
        ) from None


NO_ANSWER_SOURCE = (
    "gcs-utm: nothing could answer the pilot prompt (stdin is not a terminal and no answer "
    "source is set); add --auto-accept or --auto-reject for a scripted run, or --mqtt to "
    "take answers from a remote pilot station"
)


def _operator(args: argparse.Namespace, mqtt: bool) -> str | None:
    """Who answers recommendations: the dashboard (a terminal both ways), the line prompt
    (stdin a terminal, --headless or output piped), MQTT only, or --auto-*. None: nobody."""
    from gcs_utm.app import OperatorMode

    if args.auto_accept:
        return OperatorMode.AUTO_ACCEPT
    if args.auto_reject:
        return OperatorMode.AUTO_REJECT
    if sys.stdin.isatty():
        if not args.headless and sys.stdout.isatty():
            return OperatorMode.DASHBOARD
        return OperatorMode.LINE
    return OperatorMode.NONE if mqtt else None


def _options(args: argparse.Namespace, operator: str) -> Any:
    from gcs_utm.app import RunOptions

    return RunOptions(
        speed=args.speed,
        headless=args.headless or operator != "dashboard",
        operator=operator,
        reject_first=args.reject_first,
        external=args.external,
        fly=getattr(args, "fly", False),
        link=args.link,
        mqtt=args.mqtt,
        out_dir=args.out,
        duration_s=args.duration,
        figures=not args.no_figures,
        record_dir=args.record,
    )


def _settings(args: argparse.Namespace) -> Any:
    from gcs_utm.config import ConfigError
    from gcs_utm.settings import load_settings

    try:
        return load_settings(args.config)
    except ConfigError as exc:
        print(f"gcs-utm: {exc}", file=sys.stderr)
        return None


def summary_text(report: Report, path: Path) -> str:
    """A few lines about a run: threats, decisions, flown separation, intrusions."""
    lines = [
        f"scenario {report.scenario}: {len(report.threats)} threats, "
        f"{len(report.recommendations)} recommendations, report {path} "
        f"({report.wall_clock_s:.1f} s wall clock)",
    ]
    for r in report.recommendations:
        score = "" if r.cost is None else f" (cost {r.cost}, risk {r.risk})"
        who = f" by {r.answered_by} ({r.answered_via})" if r.answered_by else ""
        lines.append(
            f"  {r.uas}: {r.threat_kind} -> {r.maneuver}{score}, "
            f"v{r.version} {r.decision}{who}, "
            + ("verified on the vehicle" if r.verified else f"{r.state}")
        )
    for s in report.separation:
        # one set of minima (the pair's effective minima, the verdict's), and the distances
        # at the closest normalised approach (the instant that decides it)
        lines.append(
            f"  separation {s.pair[0]}-{s.pair[1]} (minima {s.minimum_horizontal_m:g} m "
            f"horizontal / {s.minimum_vertical_m:g} m vertical): closest at "
            f"{s.horizontal_at_closest_m} m horizontal, {s.vertical_at_closest_m} m vertical: "
            + ("LOSS OF SEPARATION" if s.loss_of_separation else "kept")
        )
    if report.truth is not None:
        for p in report.truth.pairs:
            lines.append(
                f"  flown {p.pair[0]}-{p.pair[1]} (minima {p.minimum_horizontal_m:g} m "
                f"horizontal / {p.minimum_vertical_m:g} m vertical): closest at "
                f"{p.horizontal_at_closest_m} m horizontal, {p.vertical_at_closest_m} m "
                f"vertical: " + ("LOSS OF SEPARATION" if p.loss_of_separation else "kept")
            )
        for flown in report.truth.intrusions:
            lines.append(
                f"  FLOWN INTRUSION {flown.uas} into {flown.geofence} at {flown.first_at_s} s "
                f"for {flown.duration_s:g} s"
            )
    for g in report.geofence_intrusions:
        lines.append(f"  INTRUSION {g.uas} into {g.geofence} at {g.first_at_s} s")
    return "\n".join(lines)


def _run_one(path: Path, args: argparse.Namespace, *, last: bool = True) -> int:
    """Run one scenario; 0 ok, 2 refused, 3 the operator ended the run (``q``)."""
    from gcs_utm.app import configure_interpreter, report_path, run_scenario_blocking
    from gcs_utm.scenario import ScenarioError
    from gcs_utm.services.recorder import RecordError

    prepared = _prepare(args)
    if prepared is None:
        return 2
    settings, operator, options = prepared
    configure_interpreter()
    try:
        report = run_scenario_blocking(path, settings, options)
    except (ScenarioError, RecordError) as exc:
        print(f"gcs-utm: {exc}", file=sys.stderr)
        return 2
    text = summary_text(report, report_path(options.out_dir, report.scenario))
    print(text)
    return _after_run(report, text, operator, args, last=last)


def _prepare(args: argparse.Namespace) -> tuple[Any, Any, Any] | None:
    """(settings, operator mode, run options) of a scenario run, or None after printing why
    the run is refused."""
    settings = _settings(args)
    if settings is None:
        return None
    operator = _operator(args, args.mqtt or settings.mqtt.enabled)
    if operator is None:
        print(NO_ANSWER_SOURCE, file=sys.stderr)
        return None
    try:
        options = _options(args, operator)
    except ValueError as exc:
        print(f"gcs-utm: {exc}", file=sys.stderr)
        return None
    return settings, operator, options


def _after_run(
    report: Any, text: str, operator: Any, args: argparse.Namespace, *, last: bool
) -> int:
    """0, or 3 when the operator ended the run or closed the dashboard's summary before the
    last scenario of a demo."""
    from gcs_utm.app import OperatorMode

    if report.operator_quit:
        return 3
    if operator == OperatorMode.DASHBOARD and not args.headless:
        from gcs_utm.dashboard.summary import SummaryApp

        title = f"gcs-utm: {report.scenario} done"
        if not SummaryApp(text, title=title, last=last).run() and not last:
            return 3
    return 0


def _run(args: argparse.Namespace) -> int:
    code = _run_one(args.scenario, args)
    return 0 if code == 3 else code


def demo_scenario(name: str) -> Path:
    """An embedded scenario file (shipped in the package as gcs_utm/data/scenarios)."""
    ref = resources.files("gcs_utm") / "data" / "scenarios" / name
    return Path(str(ref))


def _demo(args: argparse.Namespace) -> int:
    for i, name in enumerate(DEMO_SCENARIOS):
        code = _run_one(demo_scenario(name), args, last=i == len(DEMO_SCENARIOS) - 1)
        if code == 3:  # the operator pressed q: the whole demo ends
            return 0
        if code != 0:
            return code
    return 0


def _serve(args: argparse.Namespace) -> int:
    from gcs_utm.app import OperatorMode, configure_interpreter, serve

    settings = _settings(args)
    if settings is None:
        return 2
    from gcs_utm.config import ConfigError
    from gcs_utm.preflight import check_resources

    try:  # what serve's start opens (config check runs the same)
        check_resources(settings, source=args.config or "(default settings)")
    except ConfigError as exc:
        print(f"gcs-utm: {exc}", file=sys.stderr)
        return 2
    operator = (
        OperatorMode.AUTO_ACCEPT
        if args.auto_accept
        else OperatorMode.AUTO_REJECT
        if args.auto_reject
        else OperatorMode.DASHBOARD
        if sys.stdout.isatty() and sys.stdin.isatty() and not args.headless
        else OperatorMode.LINE
        if sys.stdin.isatty()
        else OperatorMode.NONE
    )
    headless = args.headless or operator != OperatorMode.DASHBOARD
    from gcs_utm.services.recorder import RecordError
    from gcs_utm.store import StoreError

    configure_interpreter()
    try:
        return asyncio.run(
            serve(
                settings,
                db_path=args.db,
                operator=operator,
                headless=headless,
                speed=args.speed,
                record_dir=args.record,
                cluster=args.cluster,
            )
        )
    except (StoreError, RecordError, ConfigError) as exc:  # a store, --record DIR or link
        print(f"gcs-utm: {exc}", file=sys.stderr)  # that cannot be used
        return 2
