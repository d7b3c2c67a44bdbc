"""Resolutions that hold in flight: a seeded set of generated encounters (every kind, 2-6 UAS,
multirotors and fixed wings, geofences) flown end to end in fast time with every
recommendation accepted. Every predicted loss of separation must be avoided, no accepted plan
may create a loss, and no UAS may enter a geofence (``gcs-utm eval --generate 20 --seed 7``
reproduces the set; docs/evaluation.md explains the counts)."""

from __future__ import annotations

import pytest

from gcs_utm.eval.generator import KINDS, generate, write_encounters
from gcs_utm.eval.run import EvalOptions, run_eval
from gcs_utm.eval.summary import EvalSummary, markdown
from gcs_utm.settings import Settings

SEED = 7
N = 20

pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(900)]


@pytest.fixture(scope="module")
def summary(tmp_path_factory: pytest.TempPathFactory) -> EvalSummary:
    assert {e.kind for e in generate(N, SEED)} == set(KINDS)
    out = tmp_path_factory.mktemp("classic")
    paths = write_encounters(out / "scenarios", N, SEED)
    return run_eval(paths, Settings(), EvalOptions(out_dir=out, jobs=2))


def test_the_classic_set_runs(summary: EvalSummary) -> None:
    table = markdown(summary)
    s = summary.totals
    assert s.failed_runs == 0, table
    assert s.predicted_losses >= N, table  # the set does bring UAS into conflict


def test_the_classic_set_runs_without_an_intrusion(summary: EvalSummary) -> None:
    assert summary.totals.geofence_intrusions == 0, markdown(summary)


def test_every_predicted_loss_is_avoided_in_closed_loop(summary: EvalSummary) -> None:
    table = markdown(summary)
    s = summary.totals
    assert s.losses_created_by_accepted_plans == 0, table
    assert s.predicted_losses_flown == 0, table
    assert s.share_avoided == 1.0, table
