"""``gcs-utm bench eval``: the closed loop's speed over a generated set, as JSON."""

from __future__ import annotations

import argparse

import pytest

from gcs_utm.bench import eval as bench_eval

pytestmark = [pytest.mark.network, pytest.mark.timeout(120)]


def _args(**over: object) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    bench_eval.add_arguments(p)
    args = p.parse_args([])
    for k, v in over.items():
        setattr(args, k, v)
    return args


def test_bench_eval_reports_the_median_speed_of_its_runs() -> None:
    [row] = bench_eval.run(_args(n=2, repeats=2, profile="classic"))
    assert row["benchmark"] == "eval" and row["n"] == 2 and row["failed_runs"] == 0
    assert len(row["encounters_per_minute_all"]) == 2
    assert min(row["encounters_per_minute_all"]) <= row["encounters_per_minute"]
    assert row["encounters_per_minute"] <= max(row["encounters_per_minute_all"])
    assert row["cpu_s_per_encounter"] > 0.0


def test_bench_eval_refuses_an_empty_set_by_name() -> None:
    with pytest.raises(ValueError, match="--n, --repeats and --jobs"):
        bench_eval.run(_args(n=0))
