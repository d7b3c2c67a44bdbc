"""Options and commands in a pilot's words (gcs_utm/core/emergency/wording.py): the exact
text for each kind of action, the separation in metres against the minima it was judged by,
and the one-line why."""

from __future__ import annotations

from dataclasses import replace

import pytest

from gcs_utm.core.emergency.wording import command_text, option_text, why_text
from gcs_utm.model import (
    Alternative,
    Closest,
    Command,
    CommandKind,
    Maneuver,
    OperationId,
    Position,
    Recommendation,
    RecommendationId,
    ThreatId,
    ThreatKind,
)

OP = OperationId("UAS1")
NEAR_UAS2 = Closest(
    other="UAS2", horizontal_m=12.0, vertical_m=62.4, min_horizontal_m=50.0, min_vertical_m=30.0
)


def _alt(m: Maneuver, **kw: object) -> Alternative:
    base: dict[str, object] = {"extra_length_m": 36.0, "extra_time_s": 21.0, "offset_m": 52.2}
    return Alternative(
        operation_id=OP,
        maneuver=m,
        plan=None,
        cost=0.26,
        risk=0.16,
        **{**base, **kw},  # type: ignore[arg-type]
    )


@pytest.mark.parametrize(
    ("alt", "text"),
    [
        (
            _alt(Maneuver.GO_DOWN, closest=NEAR_UAS2, fence_distance_m=120.0),
            "Descend up to 52 m below the plan: 21 s and 36 m more flight; keeps 62 m "
            "vertically from UAS2 (min 50 m h / 30 m v); 120 m from geofences",
        ),
        (
            _alt(
                Maneuver.GO_UP,
                closest=replace(NEAR_UAS2, horizontal_m=80.0, vertical_m=3.0),
            ),
            "Climb up to 52 m above the plan: 21 s and 36 m more flight; keeps 80 m "
            "horizontally from UAS2 (min 50 m h / 30 m v)",
        ),
        (
            _alt(Maneuver.GO_RIGHT, offset_m=80.0, extra_time_s=4.0, extra_length_m=61.0),
            "Turn right, up to 80 m off the plan: 4 s and 61 m more flight",
        ),
        (
            _alt(Maneuver.GO_LEFT, offset_m=None, extra_time_s=0.2, extra_length_m=0.3),
            "Turn left: no extra flight",
        ),
        (
            _alt(Maneuver.DELAY, extra_time_s=20.0, extra_length_m=0.0),
            "Hold 20 s where it is, then fly the plan: 20 s and 0 m more flight",
        ),
        (
            _alt(Maneuver.REROUTE, offset_m=140.0, fence_distance_m=18.6),
            "Reroute around the geofence, up to 140 m off the plan: 21 s and 36 m more "
            "flight; 19 m from geofences",
        ),
        (
            _alt(Maneuver.BACK_TO_PLAN, extra_time_s=0.0, extra_length_m=0.0),
            "Return to the plan: no extra flight",
        ),
        (
            _alt(Maneuver.ESCAPE, fence_distance_m=-4.0),
            "Leave the geofence by the shortest way: 21 s and 36 m more flight; enters a "
            "geofence by 4 m",
        ),
        (
            _alt(Maneuver.KEEP_PLAN, extra_time_s=None, extra_length_m=None, offset_m=None),
            "Keep the current plan",
        ),
        (
            _alt(
                Maneuver.GO_UP,
                closest=Closest(
                    other="UAS3",
                    horizontal_m=30.0,
                    vertical_m=40.0,
                    min_horizontal_m=45.0,
                    min_vertical_m=45.0,
                    spherical=True,
                ),
            ),
            "Climb up to 52 m above the plan: 21 s and 36 m more flight; keeps 50 m from "
            "UAS3 (min 45 m)",
        ),
    ],
)
def test_each_action_reads_as_verb_size_and_effect(alt: Alternative, text: str) -> None:
    assert option_text(alt) == text


@pytest.mark.parametrize(
    ("cmd", "text"),
    [
        (
            Command(kind=CommandKind.HOLD, operation_id=OP),
            "Hold at the current position (brake and hover; a fixed wing circles)",
        ),
        (Command(kind=CommandKind.LAND, operation_id=OP), "Land now where it is"),
        (Command(kind=CommandKind.RTL, operation_id=OP), "Return to launch"),
        (
            Command(
                kind=CommandKind.GOTO,
                operation_id=OP,
                target=Position(lat_deg=60.0, lon_deg=24.0, alt_amsl_m=152.4),
            ),
            "Climb or descend in place to 152 m AMSL and hover",
        ),
    ],
)
def test_commands_read_as_what_the_vehicle_does(cmd: Command, text: str) -> None:
    assert command_text(cmd) == text


def test_a_goto_in_place_says_climb_or_descend_by_how_much_when_the_altitude_is_known() -> None:
    goto = Command(
        kind=CommandKind.GOTO,
        operation_id=OP,
        target=Position(lat_deg=60.0, lon_deg=24.0, alt_amsl_m=152.4),
    )
    assert command_text(goto, 120.0) == "Climb 32 m in place to 152 m AMSL and hover"
    assert command_text(goto, 180.0) == "Descend 28 m in place to 152 m AMSL and hover"


def _rec(selected: Alternative | None, *alternatives: Alternative, **kw: object) -> Recommendation:
    return Recommendation(
        id=RecommendationId("t1/UAS1"),
        version=1,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=0.0,
        deadline_t_s=20.0,
        selected=selected,
        alternatives=alternatives,
        **kw,  # type: ignore[arg-type]
    )


def test_why_names_what_made_the_proposed_option_the_choice() -> None:
    cheap = _alt(Maneuver.GO_DOWN)
    dear = replace(_alt(Maneuver.GO_UP), cost=0.5)
    risky = replace(_alt(Maneuver.GO_LEFT), cost=0.1, risk=0.4)
    assert why_text(_rec(cheap)) == "the only option that keeps the minima"
    assert why_text(_rec(cheap, dear, replace(dear, risk=0.2))) == (
        "lowest cost and risk among 3 safe options"
    )
    assert why_text(_rec(cheap, dear, risky)) == "lowest risk among 3 safe options"
    assert why_text(_rec(replace(cheap, risk=0.5), dear)) == "lowest cost among 2 safe options"
    inside = replace(_alt(Maneuver.REROUTE), fence_distance_m=-3.0, cost=0.0, risk=0.0)
    clear = replace(_alt(Maneuver.ESCAPE), fence_distance_m=5.0)
    assert why_text(_rec(clear, inside)) == "the only option of 2 clearing the geofences"
    assert why_text(_rec(replace(dear, risk=0.9), cheap)) == (
        "best together with the other UAS's options (joint selection among 2)"
    )
    hold = _rec(None, command=Command(kind=CommandKind.HOLD, operation_id=OP), reason="expired")
    assert why_text(hold) == "safe command: expired"


def test_a_joint_decision_words_the_separation_from_the_other_uas_in_metres() -> None:
    """TD scores options against traffic outside the conflict; the words say how far each
    option keeps from the other UAS's chosen plan, against the pair's effective minima (the
    vertical minimum is the sum of the operational volumes here, not the configured one)."""
    import sys
    from pathlib import Path

    from gcs_utm.bench import deconfliction as sc

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_em import MON, make_em

    snap, threat = sc.scenario_los_2uas()
    ops = snap.operations
    floor_m = sum(o.operational_volume_m for o in ops.values())
    h_min, v_min = MON.effective_minima(*(o.operational_volume_m for o in ops.values()))
    assert v_min == floor_m > MON.separation_vertical_m  # the OV floor decides
    (rec,) = make_em().on_threat(threat, snap).recommendations
    other = next(k for k in threat.uas_ids if k != rec.operation_id)
    for alt in (rec.selected, *rec.alternatives):
        assert alt is not None and alt.closest is not None
        assert alt.closest.other == other
        assert (alt.closest.min_horizontal_m, alt.closest.min_vertical_m) == (h_min, v_min)
        assert f"from {other} (min {h_min:.0f} m h / {v_min:.0f} m v)" in option_text(alt)
