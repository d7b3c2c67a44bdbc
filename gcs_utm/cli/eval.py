"""``gcs-utm eval SCENARIO... --out DIR [--jobs N] [--auto-reject] [--generate N --seed S
--profile P]``:
fast-time closed-loop evaluation (see :mod:`gcs_utm.eval`)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from gcs_utm.eval.generator import PROFILES


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "eval",
        help="run scenarios end to end in fast time with an automatic operator and "
        "summarise the resolutions (JSON and markdown)",
    )
    p.add_argument("scenarios", type=Path, nargs="*", help="scenario TOML or GAUSS JSON files")
    p.add_argument("--out", type=Path, required=True, help="folder for reports and summary")
    p.add_argument(
        "--jobs",
        type=int,
        default=os.cpu_count() or 1,
        help=f"scenarios run at once, one process each (default: this machine's "
        f"{os.cpu_count()} CPUs)",
    )
    p.add_argument("--config", type=Path, default=None, help="settings TOML")
    p.add_argument(
        "--auto-reject",
        action="store_true",
        help="reject every recommendation (default: accept every one)",
    )
    p.add_argument(
        "--generate",
        type=int,
        default=0,
        metavar="N",
        help="also generate N encounters (written to OUT/scenarios) and run them",
    )
    p.add_argument("--seed", type=int, default=1, help="seed of the generated encounters")
    p.add_argument(
        "--profile",
        choices=(*PROFILES, "all"),
        default="classic",
        help="what the generated encounters stress (docs/evaluation.md); all: a mix cycling "
        "through every profile",
    )
    p.set_defaults(func=_eval)


def _eval(args: argparse.Namespace) -> int:
    from gcs_utm.app import OperatorMode, configure_interpreter
    from gcs_utm.config import ConfigError
    from gcs_utm.eval.generator import write_encounters
    from gcs_utm.eval.run import EvalOptions, run_eval
    from gcs_utm.eval.summary import markdown
    from gcs_utm.settings import load_settings

    missing = [str(p) for p in args.scenarios if not p.is_file()]
    if missing:
        print(f"gcs-utm eval: no such scenario file: {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.generate < 0 or args.jobs < 1:
        print("gcs-utm eval: --generate must be >= 0 and --jobs >= 1", file=sys.stderr)
        return 2
    paths = list(args.scenarios)
    if args.generate:
        paths += write_encounters(args.out / "scenarios", args.generate, args.seed, args.profile)
    if not paths:
        print("gcs-utm eval: give scenario files or --generate N", file=sys.stderr)
        return 2
    try:
        settings = load_settings(args.config)
    except ConfigError as exc:
        print(f"gcs-utm eval: {exc}", file=sys.stderr)
        return 2
    configure_interpreter()
    operator = OperatorMode.AUTO_REJECT if args.auto_reject else OperatorMode.AUTO_ACCEPT
    summary = run_eval(
        paths, settings, EvalOptions(out_dir=args.out, jobs=args.jobs, operator=operator)
    )
    print(markdown(summary))
    print(f"reports in {args.out / 'reports'}, summary in {args.out / 'summary.json'}")
    return 1 if summary.totals.failed_runs else 0
