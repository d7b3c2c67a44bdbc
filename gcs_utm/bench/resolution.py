"""Resolutions flown in closed loop: a generated set of encounters (crossing, head-on,
overtaking, vertical, near-threshold; 2-6 UAS, multirotors and fixed wings, some with a
geofence) run end to end in fast time with every recommendation accepted. Reports the share
of predicted losses of separation avoided, losses created by accepted plans, geofence
intrusions and the median extra distance of accepted plans (``gcs_utm.eval.summary``).

Not part of ``gcs-utm bench`` without a name (it runs for minutes): ``gcs-utm bench
resolution --json``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path
from typing import Any

NAME = "resolution"
IN_ALL = False  # minutes, not seconds: only when asked for by name


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n", type=int, default=200, help="encounters (default 200)")
    p.add_argument("--seed", type=int, default=1, help="seed of the encounter set")
    p.add_argument(
        "--jobs", type=int, default=os.cpu_count() or 1, help="runs at once (default: CPUs)"
    )
    p.add_argument(
        "--out", type=Path, default=None, help="keep reports and summary here (default: none)"
    )


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    from gcs_utm.eval.generator import write_encounters
    from gcs_utm.eval.run import EvalOptions, run_eval
    from gcs_utm.settings import Settings

    with tempfile.TemporaryDirectory(prefix="gcs-utm-resolution-") as tmp:
        out = args.out or Path(tmp)
        paths = write_encounters(out / "scenarios", args.n, args.seed)
        s = run_eval(paths, Settings(), EvalOptions(out_dir=out, jobs=args.jobs))
    t = s.totals
    return [
        {
            "benchmark": "resolution",
            "n": t.scenarios,
            "seed": args.seed,
            "failed_runs": t.failed_runs,
            "predicted_losses": t.predicted_losses,
            "losses_avoided": t.losses_avoided,
            "share_avoided": t.share_avoided,
            "predicted_losses_flown": t.predicted_losses_flown,
            "losses_created_by_accepted_plans": t.losses_created_by_accepted_plans,
            "losses_missed": t.losses_missed,
            "geofence_intrusions": t.geofence_intrusions,
            "escalations": t.escalations,
            "escalations_without_command": t.escalations_without_command,
            "encounters_per_minute": s.encounters_per_minute,
            "accepted_plans": t.accepted_plans,
            "median_extra_distance_m": s.median_extra_length_m,
            "median_extra_time_s": s.median_extra_time_s,
            "median_detection_to_verified_upload_s": s.median_detection_to_verified_upload_s,
            "wall_clock_s": s.wall_clock_s,
        }
    ]
