"""``gcs-utm plot REPORT.json``: figures (top view, 3D) plus GeoJSON and KML of a run."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("plot", help="draw figures and GeoJSON/KML from a run report")
    p.add_argument("report", type=Path, help="JSON report written by `gcs-utm run`")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: beside it)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from gcs_utm.dashboard.plot import ReportError, export_all, load_report
    from gcs_utm.dashboard.plotting import PlotsUnavailableError, require_plots

    try:
        require_plots()
        report = load_report(args.report)
    except (ReportError, PlotsUnavailableError) as exc:
        print(f"gcs-utm plot: {exc}", file=sys.stderr)
        return 2
    out = args.out or args.report.parent
    summary = export_all(report, out, stem=args.report.stem)
    print(
        f"{summary.plans} plans, {summary.alternatives} alternatives, {summary.tracks} tracks, "
        f"{summary.geofences} geofences, {summary.conflict_points} conflict points"
    )
    for f in summary.files:
        print(f)
    return 0
