"""Use case 1 end to end with a pilot who accepts an alternative instead of the proposed
option: that alternative is uploaded, verified and flown, and the report, the store's
``answers`` table and the audit name it, its version and who chose it."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from gcs_utm.app import OperatorMode, RunOptions, Runtime, run_scenario_blocking
from gcs_utm.messages import PilotAnswer, PilotDecision
from gcs_utm.model import Recommendation, RecommendationState
from gcs_utm.settings import Settings
from gcs_utm.store import Store

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.network, pytest.mark.timeout(240)]


class ChoosingPilot:
    """Accepts the first alternative with a plan and another manoeuvre than the proposed
    one, on the first proposal that has such an alternative."""

    def __init__(self, rt: Runtime) -> None:
        self.rt = rt
        self.chosen: list[tuple[Recommendation, str]] = []

    async def present(self, rec: Recommendation) -> None:
        if self.chosen or not rec.alternatives or rec.selected is None:
            return
        proposed = rec.selected.maneuver
        pick = next(
            (a for a in rec.alternatives if a.plan is not None and a.maneuver is not proposed),
            None,
        )
        if pick is None:
            return
        self.chosen.append((rec, pick.maneuver.value))
        await self.rt.usm.answer(
            PilotAnswer(
                recommendation_id=rec.id,
                version=rec.version,
                decision=PilotDecision.ACCEPT,
                t_s=self.rt.clock.now_s(),
                operator="pilot-1",
                source="dashboard",
                alternative_index=rec.alternatives.index(pick),
            )
        )

    async def update(self, rec: Recommendation) -> None:
        return None


def test_an_accepted_alternative_is_flown_and_named(tmp_path: Path) -> None:
    pilots: list[ChoosingPilot] = []

    async def attach(rt: Runtime) -> None:
        pilot = ChoosingPilot(rt)
        pilots.append(pilot)
        rt.usm.attach_operator(pilot)

    # fast time: deterministic, so the proposal (and its alternatives) is the same every run
    options = RunOptions(
        speed=math.inf, headless=True, operator=OperatorMode.NONE, out_dir=tmp_path, figures=False
    )
    report = run_scenario_blocking(
        ROOT / "config" / "scenarios" / "use_case_1.toml", Settings(), options, on_runtime=attach
    ).to_json()
    (pilot,) = pilots
    assert pilot.chosen, report["recommendations"]
    rec, maneuver = pilot.chosen[0]
    row: dict[str, Any] = next(
        r for r in report["recommendations"] if r["id"] == rec.id and r["version"] == rec.version
    )
    assert (row["decision"], row["maneuver"], row["verified"]) == ("accepted", maneuver, True)
    assert (row["answered_by"], row["answered_via"]) == ("pilot-1", "dashboard")
    uas = next(op for op in report["operations"] if op["id"] == rec.operation_id)
    assert uas["plans"][-1]["reason"].endswith(maneuver)
    store = Store(tmp_path / "use_case_1.sqlite")
    try:
        answers = store.load_answers(rec.id)
        assert [(a.version, a.operator, a.source) for a in answers] == [
            (rec.version, "pilot-1", "dashboard")
        ]
        audit = [e for e in store.load_audit() if e.action == "answer_accept"]
        assert audit and audit[0].detail["maneuver"] == maneuver
        stored = {
            (r.version, r.state): r
            for r in store.load_recommendations(latest_only=False)
            if r.id == rec.id
        }
        applied = stored[(rec.version, RecommendationState.APPLIED)]
        assert applied.selected is not None and applied.selected.maneuver.value == maneuver
    finally:
        store.close()
