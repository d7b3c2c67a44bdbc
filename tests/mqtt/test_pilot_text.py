"""What ``gcs-utm pilot`` reads and prints (gcs_utm/cli/pilot_text.py): typed answers,
option rows -> alternative_index, a recommendation as the bridge encodes it."""

from __future__ import annotations

import dataclasses
import json

import pytest
from test_bridge import _rec

from adapters.mqtt.encode import encode_recommendation
from gcs_utm.cli.pilot_text import (
    Choice,
    ack_text,
    alternative_index,
    option_summary,
    parse_choice,
    recommendation_text,
    status_text,
)
from gcs_utm.model import Command, CommandKind, OperationId


def _json(**changes: object) -> dict[str, object]:
    rec = dataclasses.replace(_rec(1), **changes)  # type: ignore[arg-type]
    return json.loads(encode_recommendation(rec))  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    ("line", "choice"),
    [
        ("a", Choice(accept=True)),
        (" A 2 \n", Choice(accept=True, row=2)),
        ("accept 0", Choice(accept=True, row=0)),
        ("r", Choice(accept=False)),
        ("Reject\n", Choice(accept=False)),
    ],
)
def test_parse_choice_accepts_a_a_n_and_r(line: str, choice: Choice) -> None:
    assert parse_choice(line) == choice


@pytest.mark.parametrize("line", ["", "x", "a b", "a -1", "a 1 2", "r 1", "yes"])
def test_parse_choice_names_what_is_accepted(line: str) -> None:
    with pytest.raises(ValueError, match=r"is not an answer; answer with: a .*a N .*r \(reject\)"):
        parse_choice(line)


def test_rows_map_to_alternative_index_like_the_console_prompt() -> None:
    rec = _json()  # selected + 2 alternatives: rows 0 (proposed), 1, 2
    assert [alternative_index(rec, r) for r in (None, 0, 1, 2)] == [None, None, 0, 1]
    with pytest.raises(ValueError, match=r"option 3 does not exist \(options 0..2\)"):
        alternative_index(rec, 3)
    no_selected = _json(selected=None)  # rows are the alternatives themselves
    assert [alternative_index(no_selected, r) for r in (0, 1)] == [0, 1]


def test_recommendation_text_shows_uas_threat_options_and_deadline() -> None:
    text = recommendation_text(_json())
    lines = text.splitlines()
    assert lines[0] == (
        "recommendation rec-1 v1 for UAS op-alice-1: loss of separation (threat thr-1)"
    )
    assert lines[1] == "  why: lowest cost among 3 safe options"
    # each option in the pilot's words (the recommendation's "text"), scores behind details
    assert lines[2] == "  [0] Climb above the plan (proposed)"
    assert lines[3] == "  [1] Climb above the plan"
    assert lines[4] == "  [2] Hold at the current position"
    detailed = recommendation_text(_json(), details=True).splitlines()
    assert detailed[2] == "  [0] Climb above the plan [go up, cost 0.20, risk 0.10] (proposed)"
    # _rec: deadline T0 + 60 s = 2023-11-14 22:14:20 UTC
    assert "  deadline 2023-11-14 22:14:20 UTC (60 s after it was issued)" in lines
    assert lines[-1].strip().startswith("answer with: a")


def test_option_summary_reads_the_scoring_terms_of_the_detail() -> None:
    alt = {
        "maneuver": "lateral_right",
        "cost": 0.31,
        "risk": 0.02,
        "detail": "right 60 m; cost=0.31, risk=0.02, extra_distance_m=85.4, "
        "extra_time_s=-3.25, offset_m=60.0, min_separation_ratio=2.125",
        "waypoints": [],
    }
    assert option_summary(alt) == (
        "lateral right, +85 m, -3.2 s, min separation 2.12x required, cost 0.31, risk 0.02, "
        "right 60 m"
    )
    # without terms: just the manoeuvre, cost and risk
    assert option_summary({"maneuver": "hold", "cost": 0.5, "risk": 0.05}) == (
        "hold, cost 0.50, risk 0.05"
    )


def test_acknowledgements_and_state_changes_read_plainly() -> None:
    assert ack_text("accepted", "accepted", "", "r1", 2) == (
        "gcs-utm accepted the answer to recommendation r1 v2 (state accepted)"
    )
    assert "duplicate" in ack_text("duplicate", "applied", "", "r1", 2)
    assert ack_text("refused", "proposed", "deadline passed", "r1", 2) == (
        "gcs-utm refused the answer to recommendation r1 v2: deadline passed"
    )
    status = {"recommendation_id": "r1", "version": 2, "state": "expired", "reason": ""}
    assert status_text(status) == (
        "!!! EXPIRED recommendation r1 v2: nobody answered in time - no longer answerable"
    )
    applied = {**status, "state": "applied"}
    assert status_text(applied) == "recommendation r1 v2 is now applied"


def test_the_recommendation_carries_each_option_in_words() -> None:
    rec = _json()
    assert rec["text"] == "Climb above the plan"
    assert rec["why"] == "lowest cost among 3 safe options"
    assert [a["text"] for a in rec["alternatives"]] == [  # type: ignore[attr-defined]
        "Climb above the plan",
        "Hold at the current position",
    ]
    assert rec["selected"]["maneuver"] == "go_up"  # type: ignore[index]  # raw fields stay
    command = _json(command=Command(kind=CommandKind.HOLD, operation_id=OperationId("op-alice-1")))
    assert command["command"]["text"].startswith("Hold at the current position")  # type: ignore[index]
