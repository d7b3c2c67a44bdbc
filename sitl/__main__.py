"""`python -m sitl FLEET.toml` or `python -m sitl --instance I [...]`: run simulated vehicles.

One process, one asyncio loop for all vehicles; SIGINT/SIGTERM stop it cleanly.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from typing import Any

from sitl.fleet import run_fleet
from sitl.fleetfile import FleetFileError, load_fleet
from sitl.spec import SimTime, VehicleSpec


def _hostport(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return host or "127.0.0.1", int(port)


def _home(text: str) -> tuple[float, float, float]:
    parts = [float(x) for x in text.split(",")]
    if len(parts) != 3:
        raise argparse.ArgumentTypeError("expected LAT,LON,ALT_AMSL")
    return parts[0], parts[1], parts[2]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sitl", description="PX4-like simulated MAVLink vehicles"
    )
    p.add_argument("fleet", nargs="?", help="fleet TOML file (see docs/sitl.md)")
    p.add_argument("--instance", type=int, help="run one vehicle like PX4 instance I (sysid I+1)")
    p.add_argument("--kind", choices=["multirotor", "fixed_wing"], default="multirotor")
    p.add_argument("--autopilot", choices=["px4", "ardupilot"], default="px4")
    p.add_argument(
        "--gcs",
        type=_hostport,
        default=("127.0.0.1", 14550),
        help="HOST:PORT (default 127.0.0.1:14550)",
    )
    p.add_argument("--home", type=_home, help="LAT,LON,ALT_AMSL")
    p.add_argument("--speed", type=float, help="simulation speed factor (PX4_SIM_SPEED_FACTOR)")
    p.add_argument("--start-utc", type=float, help="simulated UTC at start, POSIX seconds")
    p.add_argument(
        "--bind-host", default="127.0.0.1", help="address to bind (0.0.0.0 for other hosts)"
    )
    p.add_argument("--log-level", default="INFO")
    return p


def specs_from_args(args: argparse.Namespace) -> tuple[list[VehicleSpec], float, float | None]:
    if args.fleet:
        specs, speed, start = load_fleet(args.fleet)
    elif args.instance is not None:
        kw: dict[str, Any] = {}
        if args.home:
            kw["home_lat_deg"], kw["home_lon_deg"], kw["home_alt_amsl_m"] = args.home
        specs = [
            VehicleSpec(
                instance=args.instance,
                kind=args.kind,
                autopilot=args.autopilot,
                gcs_host=args.gcs[0],
                gcs_port=args.gcs[1],
                bind_host=args.bind_host,
                **kw,
            )
        ]
        speed, start = 1.0, None
    else:
        raise SystemExit("python -m sitl: give a FLEET.toml or --instance I")
    if args.speed is not None:
        speed = args.speed
    if args.start_utc is not None:
        start = args.start_utc
    return specs, speed, start


async def _amain(specs: list[VehicleSpec], sim_time: SimTime) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await run_fleet(specs, sim_time, stop)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    try:
        specs, speed, start = specs_from_args(args)
    except FleetFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    asyncio.run(_amain(specs, SimTime(speed=speed, start_utc_s=start)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
