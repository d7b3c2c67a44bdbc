"""``gcs-utm sitl FILE [--speed N] [--gcs HOST:PORT]``: the simulated vehicles of a scenario
file, in one process, until Ctrl-C / SIGTERM.

Each vehicle of the scenario (:attr:`gcs_utm.scenario.Scenario.vehicles`) becomes a PX4-like
:class:`sitl.VehicleSpec`: instance ``i`` in file order (UDP ``18570+i`` like ``px4 -i i``;
``--ephemeral-ports`` for any free port), sysid = its operation's ``sys_id``, preloaded with its
filed plan as its mission (segment speeds from the plan's 4D timing, as ``DO_CHANGE_SPEED``),
and auto-started so that it reaches its first waypoint at the plan's start time plus its start
delay (the take-off climb is started early by ``climb / climb_rate + 2 s``). Time: the
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
from typing import TYPE_CHECKING

from gcs_utm.scenario import EventKind, Scenario, ScenarioError

if TYPE_CHECKING:
    import sitl

_log = logging.getLogger(__name__)

_START_MARGIN_S = 2.0  # arm + take-off transition before the climb starts
_DEFAULT_LEAD_S = 10.0
_FAULTS = {
    EventKind.GNSS_JAMMING: "GNSS_JAMMING",
    EventKind.SPOOFING: "SPOOFING",
    EventKind.BATTERY_DROP: "BATTERY_DROP",
    EventKind.BATTERY_DRAIN: "BATTERY_DRAIN",
    EventKind.LINK_LOSS: "LINK_LOSS",
    EventKind.PACKET_LOSS: "PACKET_LOSS",
    EventKind.MOTOR_FAILURE: "MOTOR_FAILURE",
}


def vehicle_specs(
    scenario: Scenario,
    *,
    lead_s: float,
    gcs_host: str = "127.0.0.1",
    gcs_port: int = 14550,
    ephemeral_ports: bool = False,
) -> list[sitl.VehicleSpec]:
    """The simulated vehicles of ``scenario`` (see the module docstring). ``lead_s`` is the
    simulated time between the fleet start and the scenario's t0."""
    from sitl import FaultKind, FaultSpec, MissionItemSpec, VehicleSpec

    frame = scenario.frame
    specs: list[VehicleSpec] = []
    for i, v in enumerate(scenario.vehicles):
        wps = v.plan.waypoints
        items: list[MissionItemSpec] = []
        for j, w in enumerate(wps):
            speed: float | None = None
            if j > 0:
                a = wps[j - 1]
                e0, n0 = frame.point_to_local(a.lat_deg, a.lon_deg)
                e1, n1 = frame.point_to_local(w.lat_deg, w.lon_deg)
                dist = math.dist((e0, n0, a.alt_amsl_m), (e1, n1, w.alt_amsl_m))
                dt = w.t_s - a.t_s
                speed = dist / dt if dt > 0.0 and dist > 0.0 else None
            items.append(
                MissionItemSpec(
                    lat_deg=w.lat_deg, lon_deg=w.lon_deg, alt_amsl_m=w.alt_amsl_m, speed_mps=speed
                )
            )
        climb_s = max(0.0, wps[0].alt_amsl_m - v.home.alt_amsl_m) / max(v.max_climb_rate_mps, 0.1)
        start_at = (
            lead_s + (wps[0].t_s - scenario.t0_s) + v.start_delay_s - climb_s - _START_MARGIN_S
        )
        faults = [
            FaultSpec(
                kind=FaultKind[_FAULTS[ev.kind]],
                at_s=lead_s + ev.at_s,
                duration_s=ev.duration_s,
                # a scenario's jamming strength in 0..1 is not a drift: use the default drift
                value=(
                    None
                    if ev.kind is EventKind.GNSS_JAMMING and ev.value is not None and ev.value <= 1
                    else ev.value
                ),
            )
            for ev in scenario.events
            if ev.uas == v.operation_id and ev.kind in _FAULTS
        ]
        specs.append(
            VehicleSpec(
                instance=i,
                sys_id=int(v.sys_id) if v.sys_id is not None else i + 1,
                kind=v.vehicle_kind.value,
                autopilot=v.autopilot.value if v.autopilot.value == "ardupilot" else "px4",
                home_lat_deg=v.home.lat_deg,
                home_lon_deg=v.home.lon_deg,
                home_alt_amsl_m=v.home.alt_amsl_m,
                cruise_speed_mps=v.cruise_speed_mps,
                climb_rate_mps=v.max_climb_rate_mps,
                mission=tuple(items),
                auto_start_at_s=max(0.5, start_at),
                gcs_host=gcs_host,
                gcs_port=gcs_port,
                bind_port=0 if ephemeral_ports else None,
                tcp_port=0 if ephemeral_ports else None,
                faults=tuple(faults),
                battery_capacity_s=v.endurance_s or 1800.0,
                seed=i,
            )
        )
    return specs


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
    p.add_argument("scenario", type=Path, help="scenario file (.toml, or GAUSS .json)")
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
