"""The strategic check at filing time: a plan filed into the airspace is checked against the
filed plans (one against many, on the index) and its conflicts are logged."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "monitoring"))
from helpers import FRAME, operation
from strategic_oracle import plan_vs_plans_allpairs

from gcs_utm.app import Persistence, build_runtime
from gcs_utm.clock import ManualClock
from gcs_utm.core.monitoring import MonitoringConfig
from gcs_utm.model import FlightPlan, Operation, OperationState
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.strategic import FilingCheck
from gcs_utm.settings import Settings

T0 = 1.7e9


def _line(op_id: str, y: float, t0: float = T0, reverse: bool = False) -> Operation:
    pts = [(0.0, y, 100.0, t0), (1000.0, y, 100.0, t0 + 100)]
    if reverse:
        pts = [(1000.0, y, 100.0, t0), (0.0, y, 100.0, t0 + 100)]
    return operation(op_id, pts)


def test_each_filing_is_checked_against_the_filed_plans() -> None:
    events: list[tuple[str, str]] = []
    airspace = Airspace()
    check = FilingCheck(
        FRAME,
        MonitoringConfig(),
        operations=lambda: airspace.operations,
        log_event=lambda kind, text: events.append((kind, text)),
    )
    loaded = _line("L", 0.0)  # loaded without notification (a restart)
    airspace.load([loaded], [])
    airspace._on_operation = check.on_operation  # what the app wires
    a = _line("A", 3000.0)
    airspace.add_operation(a)  # far from L: no conflict
    assert check.conflicts["A"] == [] and len(check) == 2
    b = _line("B", 0.0, reverse=True)  # head-on with L
    airspace.add_operation(b)
    (c,) = check.conflicts["B"]
    assert (c.a, c.b) == ("B", "L")
    assert check.conflicts["B"] == plan_vs_plans_allpairs(
        b.plan, b, [loaded, a], FRAME, MonitoringConfig()
    )
    assert events and events[0][0] == "strategic" and "B plan v1 conflicts with L" in events[0][1]
    # A new version of B, 10 minutes later: checked again, now clear; a state change is not.
    later = dataclasses.replace(
        b.plan,
        version=2,
        waypoints=tuple(dataclasses.replace(w, t_s=w.t_s + 600) for w in b.plan.waypoints),
    )
    airspace.replace_plan(later)
    assert check.conflicts["B"] == []
    airspace.set_state(b.id, OperationState.ACTIVE)
    assert check.counters == {"checked": 3, "in_conflict": 1, "errors": 0}
    # L ends: it leaves the index, so C on L's line conflicts with nobody.
    airspace.set_state(loaded.id, OperationState.ENDED)
    airspace.add_operation(_line("C", 0.0, reverse=True))
    assert check.conflicts["C"] == []


class _NoStore(Persistence):
    def __init__(self) -> None:
        pass

    @property
    def epoch(self) -> int:
        return 1

    def save_plan(self, plan: FlightPlan) -> None:
        pass

    def save_operation(self, op: Operation) -> None:
        pass


def test_the_service_checks_a_plan_when_it_is_filed() -> None:
    rt = build_runtime(Settings(), ManualClock(0.0), FRAME, _NoStore())
    rt.airspace.add_operation(_line("A", 0.0))
    rt.airspace.add_operation(_line("B", 0.0, reverse=True))
    texts = [e.text for e in rt.usm.events if e.kind == "strategic"]
    assert len(texts) == 1 and texts[0].startswith("B plan v1 conflicts with A")


def test_what_the_filing_found_leaves_with_the_forgotten_operation() -> None:
    """A day of traffic kept one list of conflicts (and of fence findings) per operation
    ever filed (``gcs-utm bench soak``): the retention that forgets an ended operation now
    forgets what its filing found too; the others' stay."""
    rt = build_runtime(Settings(), ManualClock(0.0), FRAME, _NoStore())
    assert rt.filing is not None and rt.retention is not None
    rt.airspace.add_operation(_line("A", 0.0))
    rt.airspace.add_operation(_line("B", 0.0, reverse=True))
    assert [c.b for c in rt.filing.conflicts["B"]] == ["A"]
    for op_id in ("A", "B"):
        rt.airspace.set_state(op_id, OperationState.ACTIVE)
    rt.airspace.set_state("A", OperationState.ENDED)
    rt.airspace.set_state("B", OperationState.ENDED)
    rt.airspace.add_operation(_line("C", 5000.0))
    rt.retention.sweep(0.0)
    assert sorted(rt.retention.sweep(rt.retention.keep_s)) == ["A", "B"]
    assert set(rt.filing.conflicts) == {"C"}
    assert set(rt.filing.fence_findings) == {"C"}
    assert len(rt.filing) == 1


def test_a_failing_check_never_refuses_a_filing(monkeypatch: pytest.MonkeyPatch) -> None:
    airspace = Airspace()
    check = FilingCheck(FRAME, MonitoringConfig(), operations=lambda: airspace.operations)
    airspace._on_operation = check.on_operation

    def broken(*_a: object) -> None:
        raise RuntimeError("bug")

    monkeypatch.setattr(check._filed, "check", broken)
    airspace.add_operation(_line("A", 0.0))
    assert "A" in airspace.operations and check.counters["errors"] == 1


def _airborne_check(airborne: set[str]) -> tuple[Airspace, FilingCheck]:
    airspace = Airspace()
    check = FilingCheck(
        FRAME,
        MonitoringConfig(),
        operations=lambda: airspace.operations,
        airborne=lambda: airborne,  # type: ignore[arg-type,return-value]
    )
    airspace._on_operation = check.on_operation
    return airspace, check


def test_an_airborne_uas_after_its_plan_is_traffic_for_a_filing() -> None:
    """H's plan ended at (1000, 0) at T0 + 100 and it hovers there, in the air: a plan filed
    through that point at T0 + 200 conflicts with it (issue 30 class 1); on the ground it
    does not."""
    for airborne, expected in (({"H"}, ["H"]), (set(), [])):
        airspace, check = _airborne_check(airborne)
        airspace.add_operation(_line("H", 0.0))
        cross = operation(
            "X", [(1000.0, -1000.0, 100.0, T0 + 100), (1000.0, 1000.0, 100.0, T0 + 300)]
        )
        airspace.add_operation(cross)
        assert [c.b for c in check.conflicts["X"]] == expected
    # The airborne UAS's own re-filed plan hovers at its end while the others fly.
    airspace, check = _airborne_check({"H"})
    airspace.add_operation(cross)
    airspace.add_operation(_line("H", 0.0))
    assert [c.b for c in check.conflicts["H"]] == ["X"]


def test_at_activation_a_plan_is_checked_against_uas_that_ended_theirs_in_the_air() -> None:
    """X is filed while H's plan is still running (H's hover is checked only from H's own
    re-filing); when X's operation is activated, H has ended its plan and hovers in the air
    on X's path: the check at activation finds it."""
    airborne: set[str] = set()
    airspace, check = _airborne_check(airborne)
    airspace.add_operation(_line("H", 0.0))
    cross = operation("X", [(1000.0, -1000.0, 100.0, T0 + 100), (1000.0, 1000.0, 100.0, T0 + 300)])
    airspace.add_operation(cross)
    assert check.conflicts["X"] == []
    airborne.add("H")
    airspace.set_state(cross.id, OperationState.ACTIVE)
    assert [c.b for c in check.conflicts["X"]] == ["H"]
