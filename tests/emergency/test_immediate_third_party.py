"""An immediate command that avoids the threat's loss by running into a UAS outside the
threat: that UAS is commanded too (issue 30, a loss created by an accepted plan:
enc_3_0217, UAS2 overtaking UAS1 was told to climb in place and stopped in the path of the
fixed wing UAS5 coming up behind it 17 m lower; 47.0 m / 37.6 m against 50 / 40 m)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from gcs_utm.core.emergency.fly_on import Choice
from gcs_utm.core.emergency.immediate import choose_commands
from gcs_utm.core.emergency.third_party import better, limiting_outsider
from gcs_utm.model import AirspaceSnapshot, Operation, OperationId, TrackId, VehicleKind

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_immediate import A, B, _track, sc, sc_td

C = OperationId("C")
NOW = sc.T0_S + 89.0


def _east(op: str, x_m: float, alt_m: float, speed_mps: float, priority: int) -> Operation:
    fixed_wing = op == "C"
    o = sc.make_operation(
        op,
        [(x_m, 0, alt_m), (x_m + 3000.0, 0, alt_m)],
        speed_mps=speed_mps,
        priority=priority,
        t0_s=NOW,
        ov_m=25.0 if fixed_wing else 15.0,
    )
    if fixed_wing:
        o = replace(o, vehicle_kind=VehicleKind.FIXED_WING, max_climb_rate_mps=5.0)
    return o


def _overtaking() -> AirspaceSnapshot:
    """All east along y = 0: A (multirotor, 9.7 m/s, 100 m AMSL) ahead, B (multirotor,
    13.7 m/s, 5 m higher) 85 m behind it and overtaking, C (fixed wing, 22.4 m/s, 16.6 m
    below B) 232 m behind B."""
    rows = (("A", 0.0, 100.0, 9.7, 10), ("B", -85.0, 105.0, 13.7, 6), ("C", -317.0, 88.4, 22.4, 1))
    ops = [_east(*r) for r in rows]
    tracks = {
        TrackId(k): replace(_track(k, x, 0.0, v, 0.0, NOW), alt_amsl_m=z) for k, x, z, v, _ in rows
    }
    return replace(sc.snapshot(ops, t_s=NOW), tracks=tracks)


def test_the_uas_the_best_command_runs_into_is_commanded_too() -> None:
    """Every command of A and B loses the minima to C (B stops or slows in C's path, and
    climbs too slowly to clear it): C is a candidate too, and the choice keeps the minima
    with C commanded."""
    snap = _overtaking()
    choice = choose_commands(sc_td(), snap, [A, B], NOW + 3.0, NOW + 9.0, {A: 10, B: 6})
    assert choice is not None
    pair_only = [
        float(str(x["ratio"]))
        for x in choice.tried
        if isinstance(x["commands"], dict) and C not in x["commands"]
    ]
    assert pair_only and max(pair_only) < 1.0  # A's and B's commands alone all lose it
    assert C in choice.actions, choice.actions
    assert choice.clear and choice.ratio >= 1.0


def _choice(ratio: float, clear: bool, uas: str = "A") -> Choice:
    return Choice({OperationId(uas): None}, {OperationId(uas): "hold"}, ratio, clear, [])  # type: ignore[dict-item]


def test_a_third_uas_is_commanded_only_when_it_separates_better() -> None:
    first = _choice(0.70, False)
    assert limiting_outsider((first, C), 2, 3) == C
    assert limiting_outsider((first, None), 2, 3) is None  # a pair of the threat limits it
    assert limiting_outsider((first, C), 3, 3) is None  # no room for one more
    assert limiting_outsider((_choice(1.2, True), C), 2, 3) is None  # it keeps the minima
    assert better(first, _choice(0.72, False, "C")) is first  # not worth a third command
    assert better(first, _choice(0.80, False, "C")).ratio == 0.80
    assert better(first, _choice(1.01, True, "C")).clear
