"""``gcs-utm bench [NAME] --json``: run benchmarks and print their records."""

from __future__ import annotations

import argparse
import json
import platform
import sys
from typing import Any

from gcs_utm.bench import discover


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("bench", help="run performance benchmarks (JSON output)")
    p.add_argument("--json", action="store_true", help="print JSON (one document for all)")
    groups = p.add_subparsers(dest="bench_name", metavar="NAME")
    for name, module in discover().items():
        gp = groups.add_parser(name, help=(module.__doc__ or name).strip().splitlines()[0])
        gp.add_argument("--json", action="store_true", help="print one JSON object per line")
        module.add_arguments(gp)
    p.set_defaults(func=_run)


def _machine() -> dict[str, Any]:
    import os

    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
    }


def _run(args: argparse.Namespace) -> int:
    modules = discover()
    name = getattr(args, "bench_name", None)
    if name:
        records = modules[name].run(args)
        for rec in records:
            if args.json:
                print(json.dumps(rec))
            else:
                print(_line(rec))
        return 0
    # All benchmarks, each with its own defaults, as one JSON document.
    out: dict[str, Any] = {"machine": _machine(), "benchmarks": []}
    for mod_name, module in modules.items():
        if not getattr(module, "IN_ALL", True):
            continue  # a long benchmark runs only when named
        parser = argparse.ArgumentParser()
        module.add_arguments(parser)
        sub_args = parser.parse_args([])
        records = module.run(sub_args)
        out["benchmarks"].extend(records)
        print(f"bench {mod_name}: {len(records)} records", file=sys.stderr)
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for rec in out["benchmarks"]:
            print(_line(rec))
    return 0


def _line(rec: dict[str, Any]) -> str:
    keys = ("n", "runs", "median_ms", "min_ms", "max_ms", "p99_ms", "per_s")
    parts = [f"{k}={rec[k]}" for k in keys if k in rec]
    return f"{rec.get('benchmark')}: " + " ".join(parts)
