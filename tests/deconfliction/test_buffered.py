"""``buffered`` is an argument of TD's calls, not a state: the tracking tolerances count in
the pair minima of exactly the calls that ask for them (EM's second search and its re-check
before an upload pass False)."""

from __future__ import annotations

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import Alternative, Maneuver, Operation, ThreatKind

MON = MonitoringConfig()
CORD_MOVES = (Maneuver.GO_UP, Maneuver.GO_DOWN, Maneuver.GO_LEFT, Maneuver.GO_RIGHT)


def _pair() -> tuple[TacticalDeconfliction, Operation, Operation]:
    """A and B converge from 600 m apart to fly side by side, apart by more than the bare
    horizontal minimum with the cords' margin and less than the buffered one (a loss from
    the start could not be resolved)."""
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MON)
    margin = td.config.separation_margin_fraction
    probe = sc.make_operation("P", [(0, 0, 100), (1, 0, 100)])
    h, _ = td.pair_minima(probe, probe, buffered=False)
    hb, _ = td.pair_minima(probe, probe)
    assert hb > h * (1.0 + margin) + 1.0
    side = (h * (1.0 + margin) + hb) / 4
    a = sc.make_operation("A", [(-1000, -300, 100), (0, -side, 100), (1000, -side, 100)])
    b = sc.make_operation("B", [(-1000, 300, 100), (0, side, 100), (1000, side, 100)])
    return td, a, b


def _keep(op: Operation) -> Alternative:
    return Alternative(
        operation_id=op.id, maneuver=Maneuver.KEEP_PLAN, plan=op.plan, cost=0.0, risk=0.0
    )


def test_verify_and_compatible_count_the_tolerances_only_when_buffered() -> None:
    td, a, b = _pair()
    snap = sc.snapshot([a, b])
    assert td.verify(a.plan, a, [b], ())  # inside the buffered minima
    assert td.verify(a.plan, a, [b], (), buffered=False) == []  # outside the bare ones
    assert not td.compatible(_keep(a), _keep(b), snap)
    assert td.compatible(_keep(a), _keep(b), snap, buffered=False)
    assert td.verify(a.plan, a, [b], ())  # nothing left switched off


def test_a_search_without_buffers_moves_nothing_a_buffered_search_moves() -> None:
    td, a, b = _pair()
    snap = sc.snapshot([a, b])
    threat = sc.threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"])

    def moves(buffered: bool) -> set[Maneuver]:
        """The cords' manoeuvres offered (timing ones are offered either way)."""
        got = td.resolve_loss_of_separation(threat, snap, buffered=buffered)
        return {x.maneuver for alts in got.values() for x in alts} & set(CORD_MOVES)

    assert moves(False) == set()  # the bare minima hold: no cord is deformed
    assert moves(True)  # the buffered minima do not: the cords push A and B apart
    assert moves(False) == set()
