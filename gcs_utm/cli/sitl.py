"""``gcs-utm sitl FILE [--speed N] [--gcs HOST:PORT]``: the simulated vehicles of a scenario
file, in one process, until Ctrl-C / SIGTERM.

Each vehicle of the scenario (:attr:`gcs_utm.scenario.Scenario.vehicles`) becomes a PX4-like
:class:`sitl.VehicleSpec`: instance ``i`` in file order (UDP ``18570+i`` like ``px4 -i i``;
``--ephemeral-ports`` for any free port), sysid = its operation's ``sys_id``, preloaded with its
filed plan as its mission (segment speeds from the plan's 4D timing, as ``DO_CHANGE_SPEED``),
and started in flight at its first waypoint at the plan's start time plus its start delay
(:func:`gcs_utm.app.vehicle_specs`, shared with ``gcs-utm run``). Time: the
scenario's t0 is ``now + lead_s`` (simulated), so the vehicles boot, get a fix and are
discovered before the first plan starts. Scenario faults (GNSS jamming, spoofing, battery,
link, motor) are scheduled on the vehicle they name.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import signal
import sys
import time
from pathlib import Path

from gcs_utm.app import vehicle_specs
from gcs_utm.scenario import Scenario, ScenarioError

_log = logging.getLogger(__name__)
_DEFAULT_LEAD_S = 10.0  # simulated s before t0: vehicles boot and are discovered first


def parse_host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port) or :class:`argparse.ArgumentTypeError`."""
    host, sep, port_text = text.rpartition(":")
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not sep or not host or not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT (port 1..65535), got {text!r}")
    return host, port


async def run_sitl(
    path: Path,
    *,
    speed: float = 1.0,
    gcs: tuple[str, int] = ("127.0.0.1", 14550),
    lead_s: float = _DEFAULT_LEAD_S,
    ephemeral_ports: bool = False,
    stop: asyncio.Event | None = None,
    start_utc_s: float | None = None,
) -> None:
    """Load ``path`` and run its vehicles until ``stop`` is set (or SIGINT/SIGTERM when
    ``stop`` is None). Raises :class:`ScenarioError` for a bad scenario file."""
    from sitl import SimTime, run_fleet

    if not speed > 0.0:
        raise ValueError(f"speed must be positive, got {speed}")
    start = math.floor(time.time()) if start_utc_s is None else start_utc_s
    scenario = load_scenario(path, t0_s=start + lead_s)
    specs = vehicle_specs(
        scenario, lead_s=lead_s, gcs_host=gcs[0], gcs_port=gcs[1], ephemeral_ports=ephemeral_ports
    )
    if not specs:
        raise ScenarioError(str(path), "[[vehicle]]", "vehicles", "the scenario has no vehicles")
    own_signals = stop is None
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    if own_signals:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
    for s in specs:
        _log.info(
            "sysid %d: %d mission items, auto start at %.1f s",
            s.system_id,
            len(s.mission),
            s.auto_start_at_s or 0.0,
        )
    try:
        await run_fleet(specs, SimTime(speed, start_utc_s=start), stop)
    finally:
        if own_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)


def load_scenario(path: Path, *, t0_s: float) -> Scenario:
    from gcs_utm.scenario import load_any

    return load_any(path, t0_s=t0_s)


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "sitl",
        help="run the simulated vehicles of a scenario file (PX4-like, MAVLink over UDP)",
        description="Start every vehicle of a scenario as a PX4-like simulated vehicle "
        "(instance i: UDP 18570+i, sysid = the operation's sys_id) with its filed plan as "
        "its mission, auto-started on schedule, sending to the GCS address. Ctrl-C stops.",
    )
    p.add_argument("scenario", type=Path, help="scenario file (.toml, or GAUSS .json or .yaml)")
    p.add_argument("--speed", type=float, default=1.0, help="simulation speed factor (1)")
    p.add_argument(
        "--gcs",
        type=parse_host_port,
        default=("127.0.0.1", 14550),
        metavar="HOST:PORT",
        help="where the vehicles send (default 127.0.0.1:14550)",
    )
    p.add_argument(
        "--lead",
        type=float,
        default=_DEFAULT_LEAD_S,
        metavar="S",
        help=f"simulated seconds from start to the scenario's t0 ({_DEFAULT_LEAD_S:g})",
    )
    p.add_argument(
        "--ephemeral-ports",
        action="store_true",
        help="bind the vehicles to free ports instead of 18570+i",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    if not (args.speed > 0.0 and math.isfinite(args.speed)):
        print(f"gcs-utm sitl: --speed must be positive, got {args.speed}", file=sys.stderr)
        return 2
    try:
        asyncio.run(
            run_sitl(
                args.scenario,
                speed=args.speed,
                gcs=args.gcs,
                lead_s=args.lead,
                ephemeral_ports=args.ephemeral_ports,
            )
        )
    except (ScenarioError, OSError) as exc:
        print(f"gcs-utm sitl: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # pragma: no cover - a second Ctrl-C during shutdown
        pass
    return 0
