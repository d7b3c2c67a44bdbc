"""A fixed wing that has finished its plan circles its last waypoint; the UTM must predict
that circle, not its tangent. Encounter 149 of the 200 set (``gcs-utm bench resolution``,
seed 1): UAS3, a fixed wing, circles its end point 340 m from a geofence. Extrapolated along
the circle's tangent it was predicted into the fence; EM rerouted the finished aircraft (a
one-point plan, then back-to-plan each time it left that plan's volume), kept its operation
in progress, and it flew a predicted loss with UAS1 (docs/evaluation.md)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gcs_utm.eval.generator import encounter
from gcs_utm.eval.run import EvalOptions, run_eval
from gcs_utm.eval.summary import EvalSummary, markdown
from gcs_utm.settings import Settings

pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(300)]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[EvalSummary, Path]:
    tmp_path = tmp_path_factory.mktemp("enc149")
    enc = encounter(149, 1)
    path = tmp_path / f"{enc.name}.toml"
    path.write_text(enc.toml)
    summary = run_eval([path], Settings(), EvalOptions(out_dir=tmp_path, jobs=1))
    return summary, tmp_path / "reports" / f"{enc.name}.json"


def test_a_finished_fixed_wing_loitering_beside_a_geofence_is_left_alone(
    run: tuple[EvalSummary, Path],
) -> None:
    summary, report_path = run
    table = markdown(summary)
    s = summary.totals
    assert s.failed_runs == 0, table
    assert s.predicted_losses >= 3, table
    assert s.losses_created_by_accepted_plans == 0, table
    assert s.geofence_intrusions == 0, table
    report = json.loads(report_path.read_text())
    # The loiter circle is clear of the fence: no conflict, no reroute of a finished plan.
    geo = [t["uas"] for t in report["threats"] if t["kind"] == "GEOFENCE_CONFLICT"]
    assert geo == [], geo
    # (a new end point away from UAS1 hovering beside its circle is a separation decision,
    # docs/emergency.md "Moving an end point away from traffic")
    uas3 = next(o for o in report["operations"] if o["id"] == "UAS3")
    reasons = [p["reason"] for p in uas3["plans"]]
    assert reasons[0] == "filed" and not [r for r in reasons if "GEOFENCE" in r], reasons


def test_no_predicted_loss_is_flown(run: tuple[EvalSummary, Path]) -> None:
    """Judged from take-off to landing, including UAS3 circling after its plan (it passed
    27 m from UAS1, minima 50 / 40 m, before the UTM treated it as traffic)."""
    summary, _ = run
    assert summary.totals.predicted_losses_flown == 0, markdown(summary)
